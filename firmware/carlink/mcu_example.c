/*
 * mcu_example.c -- where a microcontroller's radio, clock and motors meet the car-link
 * core. A sketch to start a port from (the tests compile it and run it against a
 * simulated board): replace the board_* and radio_* declarations with your board's calls.
 *
 * The shape: a main loop (or an RTOS task) calls car_link_poll() often -- at least at
 * 100 Hz, so the watchdog's stop is late by 10 ms at most; every received datagram goes
 * to carlink_receive() at once (a PING is answered within 10 ms), and the motors are set
 * from carlink_motors() on every pass, also when nothing arrived: that is how the
 * watchdog stops the car when the commands stop coming.
 */
#include "carlink.h"

/* ------------------------------------------------ the board's part (declare yours) */

/* The UDP peer a datagram came from: whatever your network stack uses (lwIP: an
 * ip_addr_t and a port). An answer goes back to it. */
struct radio_peer {
    uint32_t ip;
    uint16_t port;
};

uint32_t board_millis(void);                 /* a monotonic ms clock (wraps: fine) */
int board_car_id(void);                      /* 1..255, e.g. from DIP switches or flash */
int board_link_key(uint8_t key[32]);         /* the car's key from flash or a secure
                                                element; 0 if there is one */
/* One datagram received on the car's UDP port (9000 in the lab), or 0 if none is
 * waiting; never blocks. */
size_t radio_receive(uint8_t *buffer, size_t capacity, struct radio_peer *from);
void radio_send(const uint8_t *data, size_t len, const struct radio_peer *to);
/* Set the wheel speeds for (v, omega); the vehicle's limits ([vehicle] in the fleet
 * config: speed, turn rate, accelerations) and the braking the guard counts on are the
 * firmware's to keep here (docs/carlink.md, "What else the firmware must do"). */
void motors_set(float v_mps, float omega_radps);
void board_log(const char *what, unsigned value); /* optional: a UART line */

/* ---------------------------------------------------------------- the car's part */

/* ~3.5 KB: static, never on a task's stack. Only car_link_poll() touches it. */
static carlink_state link_state;

/* 0 when the car is ready; without a key it refuses to run rather than fall back to
 * version 1 (which anyone on the network can drive). */
int car_link_setup(void)
{
    uint8_t key[CARLINK_KEY_BYTES];
    int car_id = board_car_id(), failed;
    if (car_id < 1 || car_id > 255 || board_link_key(key) != 0)
        return -1;
    failed = carlink_init(&link_state, (uint8_t)car_id, key, CARLINK_WATCHDOG_MS, CARLINK_RESYNC_MS);
    {
        volatile uint8_t *wipe = key; /* the core keeps only the HMAC's keyed state */
        size_t i;
        for (i = 0; i < sizeof key; i++)
            wipe[i] = 0;
    }
    motors_set(0.0f, 0.0f);
    return failed;
}

void car_link_poll(void)
{
    uint8_t buffer[64]; /* longer than any valid datagram: a longer one is still refused */
    struct radio_peer from;
    carlink_result result;
    size_t len;
    float v, omega;

    while ((len = radio_receive(buffer, sizeof buffer, &from)) > 0) {
        carlink_verdict verdict = carlink_receive(&link_state, buffer, len, board_millis(), &result);
        if (result.answer_len > 0)
            radio_send(result.answer, result.answer_len, &from);
        if (verdict == CARLINK_E_STOP_TAKEN)
            board_log("e-stop latched by source", result.command.source);
    }
    carlink_motors(&link_state, board_millis(), &v, &omega);
    motors_set(v, omega);
}
