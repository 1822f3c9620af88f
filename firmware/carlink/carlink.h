/*
 * carlink.h -- the car's end of trustfg's car link, in C99 for firmware.
 *
 * A reference for firmware writers: it decodes and verifies the velocity-command
 * datagrams a car process (and the operator's tools) send to a car, applies the
 * receiver's rules of bridge/carlink/receiver.py to the letter, and builds the answer to
 * a PING as bridge/carlink/answer.py does. The byte layouts are documented in
 * bridge/carlink/codec.py and answer.py; this header names the rules where they are
 * implemented (carlink.c).
 *
 * The core does no I/O, allocates nothing and calls no OS: it is handed the bytes of
 * one datagram and the time in milliseconds on a monotonic clock (wrapping at 2^32 is
 * fine), and it returns what to do -- the verdict, the decoded command, the bytes of an
 * answer to send back to the datagram's sender. carlink_motors() says at any time what
 * the motors should do. All state lives in a carlink_state the caller owns (about
 * 3.5 KB: keep it static, not on a small stack). Not thread-safe: one context calls it.
 *
 * Needs IEEE 754 binary32 floats (every MCU with or without an FPU); no doubles: the
 * stamp travels as its 64 raw bits.
 */
#ifndef CARLINK_H
#define CARLINK_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CARLINK_V1_SIZE 30u        /* version 1 command: body 26 + CRC-32 */
#define CARLINK_V2_SIZE 52u        /* version 2 command: body 36 + MAC 16 */
#define CARLINK_ANSWER_V1_SIZE 22u /* answer to a PING, version 1 */
#define CARLINK_ANSWER_V2_SIZE 44u /* answer to a PING, version 2 */
#define CARLINK_ANSWER_MAX 44u
#define CARLINK_KEY_BYTES 32u
#define CARLINK_MAC_BYTES 16u
#define CARLINK_SOURCES 256u       /* the u8 source field: 0 the car process, 1 the operator */

#define CARLINK_WATCHDOG_MS 250u   /* receiver.DEFAULT_WATCHDOG_TIMEOUT_S */
#define CARLINK_RESYNC_MS 1000u    /* receiver.DEFAULT_RESYNC_AFTER_S (version 1 only) */

/* Command flags (u16). */
#define CARLINK_E_STOP (0x0001u)
#define CARLINK_STOP (0x0002u)
#define CARLINK_RELEASE (0x0004u)
#define CARLINK_PING (0x0008u)

/* State bits of an answer (u16). */
#define CARLINK_STATE_E_STOP_LATCHED (0x0001u)
#define CARLINK_STATE_STOPPED (0x0002u)

/* What became of one datagram. The first three are taken; the rest are dropped. The
 * names (carlink_verdict_name) are receiver.FilterCounters' and CarLinkError's reasons. */
typedef enum {
    CARLINK_ACCEPTED = 0,   /* "accepted": the latest command now (rules 4, 5, 7) */
    CARLINK_E_STOP_TAKEN,   /* "e_stop": its source's E_STOP latched (rule 2) */
    CARLINK_PING_ONLY,      /* "ping": answered, not applied (rule 3) */
    CARLINK_WRONG_CAR,      /* "wrong_car": valid, for another car (rule 1) */
    CARLINK_REPEATED_SEQ,   /* "repeated_seq": the last accepted seq again */
    CARLINK_STALE_SEQ,      /* "stale_seq": an older seq */
    CARLINK_OLD_SESSION,    /* "old_session": version 2, older than its source's newest */
    /* decode errors, in the order they are checked (codec.py) */
    CARLINK_BAD_LENGTH,     /* "length" */
    CARLINK_BAD_MAGIC,      /* "magic" */
    CARLINK_BAD_VERSION,    /* "version" */
    CARLINK_BAD_CRC,        /* "crc" (version 1) */
    CARLINK_BAD_MAC,        /* "mac" (version 2) */
    CARLINK_BAD_RESERVED,   /* "reserved" (version 2) */
    CARLINK_BAD_CAR_ID,     /* "car_id": 0 */
    CARLINK_BAD_FLAGS,      /* "flags": reserved bits, or E_STOP with RELEASE */
    CARLINK_NON_FINITE,     /* "non_finite": NaN or infinity in stamp, v or omega */
    CARLINK_VERDICTS
} carlink_verdict;

#define CARLINK_FIRST_DECODE_ERROR CARLINK_BAD_LENGTH
#define CARLINK_DECODE_ERRORS (CARLINK_VERDICTS - CARLINK_FIRST_DECODE_ERROR)

/* One decoded command (codec.Command). Version 1 has no session or source (0). */
typedef struct {
    uint8_t version;
    uint8_t car_id;
    uint8_t source;
    uint16_t flags;
    uint64_t session;
    uint32_t seq;
    uint64_t stamp_bits;  /* the f64 stamp_s, its raw bits (finite) */
    float v_mps;
    float omega_radps;
} carlink_command;

/* receiver.FilterCounters. */
typedef struct {
    uint32_t accepted, resynced, e_stops, pings, wrong_car, stale_seq, repeated_seq;
    uint32_t new_session, old_session;
    uint32_t decode_errors[CARLINK_DECODE_ERRORS]; /* by verdict - CARLINK_FIRST_DECODE_ERROR */
} carlink_counters;

/* SHA-256 running state (FIPS 180-4); the HMAC keeps two, keyed once. */
typedef struct {
    uint32_t h[8];
    uint64_t bytes;
    uint8_t block[64];
    uint8_t used;
} carlink_sha256_ctx;

/* Everything the car remembers. Fields are the core's; read them through the functions. */
typedef struct {
    uint8_t car_id;
    uint8_t has_key;              /* 1: version 2 (authenticated), 0: version 1 */
    carlink_sha256_ctx inner, outer; /* HMAC-SHA256 keyed with the car's key */
    uint32_t watchdog_ms;
    uint32_t resync_ms;
    uint8_t has_last;             /* an accepted command exists */
    carlink_command last;         /* the last accepted command, of any source */
    uint32_t last_ms;             /* when it was accepted */
    uint8_t e_stop[CARLINK_SOURCES / 8];       /* bit per source: latched */
    uint8_t session_known[CARLINK_SOURCES / 8]; /* bit per source: a session seen */
    uint64_t session[CARLINK_SOURCES];          /* newest accepted session per source */
    uint32_t session_seq[CARLINK_SOURCES];      /* last accepted seq in it */
    carlink_counters counters;
} carlink_state;

/* What carlink_receive() says about one datagram. */
typedef struct {
    carlink_verdict verdict;
    carlink_command command;   /* decoded: set unless the verdict is a decode error */
    uint8_t resynced;          /* accepted under the version-1 restart rule (rule 5) */
    uint8_t new_session;       /* accepted, opening a newer session of its source (rule 4) */
    size_t answer_len;         /* 0, or send answer[0..answer_len) to the datagram's sender */
    uint8_t answer[CARLINK_ANSWER_MAX];
} carlink_result;

/* Set up a car: its id (1..255), its 32-byte key (version 2) or NULL (version 1, no
 * authentication: old firmware only), the watchdog and the version-1 resync silence in
 * ms (CARLINK_WATCHDOG_MS, CARLINK_RESYNC_MS). 0 on success; -1 for a car id of 0, a
 * watchdog of 0 or a resync not longer than the watchdog (receiver.CommandFilter). */
int carlink_init(carlink_state *s, uint8_t car_id, const uint8_t *key, uint32_t watchdog_ms,
                 uint32_t resync_ms);

/* Handle one datagram received at now_ms. Never fails for any bytes (NULL with len 0 is
 * fine). Fills *out (may be NULL) and returns the verdict. */
carlink_verdict carlink_receive(carlink_state *s, const uint8_t *data, size_t len, uint32_t now_ms,
                                carlink_result *out);

/* The command to apply at now_ms (rules 6 and 8): (0, 0) while any E_STOP is latched,
 * the latest command has STOP, none was accepted yet, or the latest is watchdog_ms old.
 * Returns 1 if that is (0, 0), else 0. Call it at the motor loop's rate. */
int carlink_motors(const carlink_state *s, uint32_t now_ms, float *v_mps, float *omega_radps);

/* The state bits an answer would carry at now_ms (CARLINK_STATE_*). */
uint16_t carlink_car_state(const carlink_state *s, uint32_t now_ms);

/* 1 while the E_STOP of `source` is latched; carlink_any_e_stop: of any source. */
int carlink_e_stop_latched(const carlink_state *s, uint8_t source);
int carlink_any_e_stop(const carlink_state *s);

/* "accepted", "mac", ... (NULL for a value outside the enum). */
const char *carlink_verdict_name(carlink_verdict verdict);

/* The primitives, exposed for tests and for a firmware that has none of its own. */
void carlink_sha256_init(carlink_sha256_ctx *ctx);
void carlink_sha256_update(carlink_sha256_ctx *ctx, const uint8_t *data, size_t len);
void carlink_sha256_final(carlink_sha256_ctx *ctx, uint8_t digest[32]);
void carlink_sha256(const uint8_t *data, size_t len, uint8_t digest[32]);
void carlink_hmac_sha256(const uint8_t *key, size_t key_len, const uint8_t *data, size_t len,
                         uint8_t mac[32]);
uint32_t carlink_crc32(const uint8_t *data, size_t len); /* CRC-32/ISO-HDLC (zlib) */

#ifdef __cplusplus
}
#endif

#endif /* CARLINK_H */
