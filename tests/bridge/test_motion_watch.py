"""A car told to drive that does not move is stuck; it is not once it moves."""

from trustfg.bridge.motion_watch import STUCK_AFTER_S, MotionWatch


def ticks(watch: MotionWatch, t0: float, seconds: float, speed: float, commanded: float, x0: float = 0.0) -> list[bool]:
    """50 Hz ticks of a car moving at ``speed`` while told ``commanded``; the changes."""
    changes = []
    for k in range(int(seconds * 50)):
        t = t0 + k / 50
        changes.append(watch.add(t, x0 + speed * (t - t0), 0.0, commanded))
    return changes


def test_a_car_told_to_drive_that_stands_is_stuck_after_the_window_and_free_once_it_moves():
    watch = MotionWatch()
    changes = ticks(watch, 0.0, 2.0, speed=0.0, commanded=0.4)
    assert watch.stuck and changes.count(True) == 1
    assert changes.index(True) / 50 >= 0.9 * STUCK_AFTER_S  # not before the window is full
    changes = ticks(watch, 2.0, 2.0, speed=0.3, commanded=0.4)
    assert not watch.stuck and changes.count(True) == 1


def test_a_car_that_moves_as_told_or_is_told_to_stand_is_not_stuck():
    moving, standing = MotionWatch(), MotionWatch()
    assert not any(ticks(moving, 0.0, 3.0, speed=0.3, commanded=0.3))
    assert not any(ticks(standing, 0.0, 3.0, speed=0.0, commanded=0.05))  # a crawl it may not show
    assert not moving.stuck and not standing.stuck


def test_clear_forgets_the_window():
    watch = MotionWatch()
    ticks(watch, 0.0, 2.0, speed=0.0, commanded=0.4)
    watch.clear()
    assert not watch.stuck and not watch.samples


def test_a_car_told_again_and_again_to_set_off_that_stands_is_stuck():
    """Commands that rise from rest at every replan (0 to 0.4 m/s in 0.2 s), none of them
    reaching the car: on average it is told to drive, so it is stuck."""
    watch = MotionWatch()
    for k in range(100):
        t = k / 50
        watch.add(t, 0.0, 0.0, 0.4 * ((t % 0.2) / 0.2))
    assert watch.stuck


def test_a_car_that_sets_off_again_and_again_as_told_is_not_stuck():
    watch, x = MotionWatch(), 0.0
    for k in range(150):
        t = k / 50
        v = 0.4 * ((t % 0.2) / 0.2)
        x += v / 50
        watch.add(t, x, 0.0, v)
    assert not watch.stuck


def test_a_car_told_to_set_off_late_in_the_window_is_not_stuck_for_its_lag():
    """Told nothing for 0.55 s, then 0.4 m/s; the car follows 0.1 s late at 1.5 m/s^2:
    on average over the window it was told 0.125 m/s and has moved at 0.02 m/s."""
    watch, x, v = MotionWatch(), 0.0, 0.0
    for k in range(int(STUCK_AFTER_S * 50)):
        t = k / 50
        told = 0.4 if t >= 0.55 else 0.0
        v = min(v + 1.5 / 50, told) if t >= 0.65 else 0.0
        x += v / 50
        watch.add(t, x, 0.0, told)
    assert not watch.stuck
