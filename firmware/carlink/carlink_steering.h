/*
 * carlink_steering.h -- the steering angle of a car that steers its front wheels.
 *
 * trustfg sends every car the same (v, omega) commands. A car-like car ([vehicle]
 * steering = "car" in the fleet config) turns them into a wheel speed v and a steering
 * angle (docs/carlink.md, "Car-like cars"):
 *
 *     delta = atan(L omega / v),   |delta| <= atan(L / R_min)
 *
 * L the wheelbase (wheelbase_m), R_min the minimum turning radius (min_turn_radius_m).
 * Below CARLINK_STEER_MIN_SPEED (1 mm/s) the angle stays where it is: omega / v names no
 * angle, and standing the car cannot turn -- trustfg never asks it to. The rule of
 * agent/vehicle.py's steering_angle, which mocap-sim's car-like cars run.
 *
 * Header only, apart from the core: it needs <math.h> (atanf, fabsf; link with -lm).
 */
#ifndef CARLINK_STEERING_H
#define CARLINK_STEERING_H

#include <math.h>

#define CARLINK_STEER_MIN_SPEED 0.001f

/* The steering angle (rad, left positive) for the command (v_mps, omega_radps);
 * ``max_steer_rad`` = atan(wheelbase / min_turn_radius); ``current_rad`` the angle the
 * wheels have now, kept while the command is to stand. */
static inline float carlink_steering_angle(float v_mps, float omega_radps, float wheelbase_m,
                                           float max_steer_rad, float current_rad)
{
    float delta;
    if (fabsf(v_mps) < CARLINK_STEER_MIN_SPEED) {
        return current_rad;
    }
    delta = atanf(wheelbase_m * omega_radps / v_mps);
    if (delta > max_steer_rad) {
        delta = max_steer_rad;
    }
    if (delta < -max_steer_rad) {
        delta = -max_steer_rad;
    }
    return delta;
}

#endif /* CARLINK_STEERING_H */
