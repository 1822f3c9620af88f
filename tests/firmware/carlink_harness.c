/* The car-link core behind flat functions for Python's ctypes (tests only): the state is
 * a buffer Python allocates, results come back as arrays of integers. */
#include "carlink.h"

#include <string.h>

size_t harness_state_size(void);
int harness_init(carlink_state *s, unsigned car_id, const uint8_t *key, uint32_t watchdog_ms, uint32_t resync_ms);
int harness_receive(carlink_state *s, const uint8_t *data, size_t len, uint32_t now_ms, uint64_t out[12],
                    uint8_t answer[CARLINK_ANSWER_MAX]);
int harness_motors(const carlink_state *s, uint32_t now_ms, float out[2]);
void harness_counters(const carlink_state *s, uint32_t out[9 + CARLINK_DECODE_ERRORS]);
unsigned harness_decode_errors(void);

size_t harness_state_size(void) { return sizeof(carlink_state); }

unsigned harness_decode_errors(void) { return (unsigned)CARLINK_DECODE_ERRORS; }

int harness_init(carlink_state *s, unsigned car_id, const uint8_t *key, uint32_t watchdog_ms, uint32_t resync_ms)
{
    if (car_id > 255)
        return -1;
    return carlink_init(s, (uint8_t)car_id, key, watchdog_ms, resync_ms);
}

/* out: verdict, version, car_id, source, flags, session, seq, stamp bits, v bits, omega
 * bits, resynced, new_session; returns the answer's length. */
int harness_receive(carlink_state *s, const uint8_t *data, size_t len, uint32_t now_ms, uint64_t out[12],
                    uint8_t answer[CARLINK_ANSWER_MAX])
{
    carlink_result r;
    uint32_t v_bits, omega_bits;
    carlink_receive(s, data, len, now_ms, &r);
    memcpy(&v_bits, &r.command.v_mps, sizeof v_bits);
    memcpy(&omega_bits, &r.command.omega_radps, sizeof omega_bits);
    out[0] = (uint64_t)r.verdict;
    out[1] = r.command.version;
    out[2] = r.command.car_id;
    out[3] = r.command.source;
    out[4] = r.command.flags;
    out[5] = r.command.session;
    out[6] = r.command.seq;
    out[7] = r.command.stamp_bits;
    out[8] = v_bits;
    out[9] = omega_bits;
    out[10] = r.resynced;
    out[11] = r.new_session;
    memcpy(answer, r.answer, CARLINK_ANSWER_MAX);
    return (int)r.answer_len;
}

int harness_motors(const carlink_state *s, uint32_t now_ms, float out[2])
{
    return carlink_motors(s, now_ms, &out[0], &out[1]);
}

void harness_counters(const carlink_state *s, uint32_t out[9 + CARLINK_DECODE_ERRORS])
{
    const carlink_counters *c = &s->counters;
    unsigned i;
    out[0] = c->accepted;
    out[1] = c->resynced;
    out[2] = c->e_stops;
    out[3] = c->pings;
    out[4] = c->wrong_car;
    out[5] = c->stale_seq;
    out[6] = c->repeated_seq;
    out[7] = c->new_session;
    out[8] = c->old_session;
    for (i = 0; i < CARLINK_DECODE_ERRORS; i++)
        out[9 + i] = c->decode_errors[i];
}
