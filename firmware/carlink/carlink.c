/*
 * carlink.c -- the car's end of trustfg's car link (see carlink.h).
 *
 * Sections: byte order and floats; SHA-256 and HMAC-SHA256 (RFC 2104, FIPS 180-4);
 * CRC-32; decoding (codec.py: the checks in its order); the receiver's rules
 * (receiver.py, rules 1-8, named where they are applied); the answer (answer.py).
 */
#include "carlink.h"

#include <string.h>

/* The float fields are IEEE 754 binary32; a float of any other size cannot hold them. */
typedef char carlink_float_is_32_bits[sizeof(float) == 4 ? 1 : -1];

/* ---------------------------------------------------------------- bytes and floats */

static uint16_t rd16(const uint8_t *p) { return (uint16_t)(p[0] | (p[1] << 8)); }

static uint32_t rd32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static uint64_t rd64(const uint8_t *p) { return (uint64_t)rd32(p) | ((uint64_t)rd32(p + 4) << 32); }

static void wr16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static void wr32(uint8_t *p, uint32_t v)
{
    wr16(p, (uint16_t)v);
    wr16(p + 2, (uint16_t)(v >> 16));
}

static void wr64(uint8_t *p, uint64_t v)
{
    wr32(p, (uint32_t)v);
    wr32(p + 4, (uint32_t)(v >> 32));
}

static float f32_of(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

/* Finite: the exponent is not all ones (no floating point needed). */
static int f32_finite(uint32_t bits) { return ((bits >> 23) & 0xFFu) != 0xFFu; }
static int f64_finite(uint64_t bits) { return ((bits >> 52) & 0x7FFu) != 0x7FFu; }

/* ------------------------------------------------------------------------- SHA-256 */

static const uint32_t K256[64] = {
    0x428a2f98u, 0x71374491u, 0xb5c0fbcfu, 0xe9b5dba5u, 0x3956c25bu, 0x59f111f1u, 0x923f82a4u, 0xab1c5ed5u,
    0xd807aa98u, 0x12835b01u, 0x243185beu, 0x550c7dc3u, 0x72be5d74u, 0x80deb1feu, 0x9bdc06a7u, 0xc19bf174u,
    0xe49b69c1u, 0xefbe4786u, 0x0fc19dc6u, 0x240ca1ccu, 0x2de92c6fu, 0x4a7484aau, 0x5cb0a9dcu, 0x76f988dau,
    0x983e5152u, 0xa831c66du, 0xb00327c8u, 0xbf597fc7u, 0xc6e00bf3u, 0xd5a79147u, 0x06ca6351u, 0x14292967u,
    0x27b70a85u, 0x2e1b2138u, 0x4d2c6dfcu, 0x53380d13u, 0x650a7354u, 0x766a0abbu, 0x81c2c92eu, 0x92722c85u,
    0xa2bfe8a1u, 0xa81a664bu, 0xc24b8b70u, 0xc76c51a3u, 0xd192e819u, 0xd6990624u, 0xf40e3585u, 0x106aa070u,
    0x19a4c116u, 0x1e376c08u, 0x2748774cu, 0x34b0bcb5u, 0x391c0cb3u, 0x4ed8aa4au, 0x5b9cca4fu, 0x682e6ff3u,
    0x748f82eeu, 0x78a5636fu, 0x84c87814u, 0x8cc70208u, 0x90befffau, 0xa4506cebu, 0xbef9a3f7u, 0xc67178f2u,
};

static uint32_t ror(uint32_t x, unsigned n) { return (x >> n) | (x << (32u - n)); }

static uint32_t rd32be(const uint8_t *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | (uint32_t)p[3];
}

/* One 64-byte block; the message schedule is a rolling window of 16 words (64 bytes of
 * stack instead of 256). */
static void sha256_block(uint32_t h[8], const uint8_t *block)
{
    uint32_t w[16], a = h[0], b = h[1], c = h[2], d = h[3], e = h[4], f = h[5], g = h[6], k = h[7];
    unsigned i;
    for (i = 0; i < 16; i++)
        w[i] = rd32be(block + 4 * i);
    for (i = 0; i < 64; i++) {
        uint32_t t1, t2;
        if (i >= 16) {
            uint32_t w2 = w[(i - 2) & 15], w15 = w[(i - 15) & 15];
            w[i & 15] += (ror(w2, 17) ^ ror(w2, 19) ^ (w2 >> 10)) + w[(i - 7) & 15]
                         + (ror(w15, 7) ^ ror(w15, 18) ^ (w15 >> 3));
        }
        t1 = k + (ror(e, 6) ^ ror(e, 11) ^ ror(e, 25)) + ((e & f) ^ (~e & g)) + K256[i] + w[i & 15];
        t2 = (ror(a, 2) ^ ror(a, 13) ^ ror(a, 22)) + ((a & b) ^ (a & c) ^ (b & c));
        k = g;
        g = f;
        f = e;
        e = d + t1;
        d = c;
        c = b;
        b = a;
        a = t1 + t2;
    }
    h[0] += a;
    h[1] += b;
    h[2] += c;
    h[3] += d;
    h[4] += e;
    h[5] += f;
    h[6] += g;
    h[7] += k;
}

void carlink_sha256_init(carlink_sha256_ctx *ctx)
{
    static const uint32_t h0[8] = {0x6a09e667u, 0xbb67ae85u, 0x3c6ef372u, 0xa54ff53au,
                                   0x510e527fu, 0x9b05688cu, 0x1f83d9abu, 0x5be0cd19u};
    memcpy(ctx->h, h0, sizeof h0);
    ctx->bytes = 0;
    ctx->used = 0;
}

void carlink_sha256_update(carlink_sha256_ctx *ctx, const uint8_t *data, size_t len)
{
    while (len > 0) {
        size_t take = 64u - ctx->used;
        if (take > len)
            take = len;
        memcpy(ctx->block + ctx->used, data, take);
        ctx->used = (uint8_t)(ctx->used + take);
        ctx->bytes += take;
        data += take;
        len -= take;
        if (ctx->used == 64u) {
            sha256_block(ctx->h, ctx->block);
            ctx->used = 0;
        }
    }
}

void carlink_sha256_final(carlink_sha256_ctx *ctx, uint8_t digest[32])
{
    uint64_t bits = ctx->bytes * 8u;
    unsigned i;
    ctx->block[ctx->used++] = 0x80u;
    if (ctx->used > 56u) {
        memset(ctx->block + ctx->used, 0, 64u - ctx->used);
        sha256_block(ctx->h, ctx->block);
        ctx->used = 0;
    }
    memset(ctx->block + ctx->used, 0, 56u - ctx->used);
    for (i = 0; i < 8; i++)
        ctx->block[56 + i] = (uint8_t)(bits >> (56 - 8 * i));
    sha256_block(ctx->h, ctx->block);
    for (i = 0; i < 32; i++)
        digest[i] = (uint8_t)(ctx->h[i / 4] >> (24 - 8 * (i % 4)));
}

void carlink_sha256(const uint8_t *data, size_t len, uint8_t digest[32])
{
    carlink_sha256_ctx ctx;
    carlink_sha256_init(&ctx);
    carlink_sha256_update(&ctx, data, len);
    carlink_sha256_final(&ctx, digest);
}

/* ------------------------------------------------------------------- HMAC-SHA256 */

/* The two hash states of HMAC after the padded key (RFC 2104): K xor ipad, K xor opad.
 * Keyed once, each MAC then costs two SHA-256 blocks over a datagram's 36 bytes. */
static void hmac_key(carlink_sha256_ctx *inner, carlink_sha256_ctx *outer, const uint8_t *key, size_t key_len)
{
    uint8_t k[64], pad[64];
    unsigned i;
    memset(k, 0, sizeof k);
    if (key_len > 64u)
        carlink_sha256(key, key_len, k); /* a key longer than a block is hashed first */
    else if (key_len > 0)
        memcpy(k, key, key_len);
    for (i = 0; i < 64; i++)
        pad[i] = (uint8_t)(k[i] ^ 0x36u);
    carlink_sha256_init(inner);
    carlink_sha256_update(inner, pad, 64);
    for (i = 0; i < 64; i++)
        pad[i] = (uint8_t)(k[i] ^ 0x5cu);
    carlink_sha256_init(outer);
    carlink_sha256_update(outer, pad, 64);
}

static void hmac_keyed(const carlink_sha256_ctx *inner, const carlink_sha256_ctx *outer, const uint8_t *data,
                       size_t len, uint8_t mac[32])
{
    carlink_sha256_ctx ctx = *inner;
    uint8_t digest[32];
    carlink_sha256_update(&ctx, data, len);
    carlink_sha256_final(&ctx, digest);
    ctx = *outer;
    carlink_sha256_update(&ctx, digest, sizeof digest);
    carlink_sha256_final(&ctx, mac);
}

void carlink_hmac_sha256(const uint8_t *key, size_t key_len, const uint8_t *data, size_t len, uint8_t mac[32])
{
    carlink_sha256_ctx inner, outer;
    hmac_key(&inner, &outer, key, key_len);
    hmac_keyed(&inner, &outer, data, len, mac);
}

/* 0 if equal; the time taken does not depend on where they differ. */
static unsigned differ(const uint8_t *a, const uint8_t *b, size_t len)
{
    unsigned diff = 0;
    size_t i;
    for (i = 0; i < len; i++)
        diff |= (unsigned)(a[i] ^ b[i]);
    return diff;
}

/* ------------------------------------------------------------------------ CRC-32 */

uint32_t carlink_crc32(const uint8_t *data, size_t len)
{
    uint32_t crc = 0xFFFFFFFFu;
    size_t i;
    unsigned k;
    for (i = 0; i < len; i++) {
        crc ^= data[i];
        for (k = 0; k < 8; k++)
            crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return crc ^ 0xFFFFFFFFu;
}

/* ---------------------------------------------------------------------- decoding */

#define KNOWN_FLAGS (CARLINK_E_STOP | CARLINK_STOP | CARLINK_RELEASE | CARLINK_PING)

/* codec.Command's checks, in its order: car id, flags, then the numbers. */
static carlink_verdict check_fields(const carlink_command *c, uint32_t v_bits, uint32_t omega_bits)
{
    if (c->car_id == 0)
        return CARLINK_BAD_CAR_ID;
    if ((c->flags & ~KNOWN_FLAGS) != 0)
        return CARLINK_BAD_FLAGS;
    if ((c->flags & CARLINK_E_STOP) && (c->flags & CARLINK_RELEASE))
        return CARLINK_BAD_FLAGS;
    if (!f64_finite(c->stamp_bits) || !f32_finite(v_bits) || !f32_finite(omega_bits))
        return CARLINK_NON_FINITE;
    return CARLINK_ACCEPTED;
}

/* Version 1, 30 bytes: length, magic, version, CRC, then the fields. */
static carlink_verdict decode_v1(const uint8_t *d, size_t len, carlink_command *c)
{
    uint32_t v_bits, omega_bits;
    if (len != CARLINK_V1_SIZE)
        return CARLINK_BAD_LENGTH;
    if (d[0] != 'T' || d[1] != 'F')
        return CARLINK_BAD_MAGIC;
    if (d[2] != 1)
        return CARLINK_BAD_VERSION;
    if (carlink_crc32(d, 26) != rd32(d + 26))
        return CARLINK_BAD_CRC;
    c->version = 1;
    c->car_id = d[3];
    c->seq = rd32(d + 4);
    c->stamp_bits = rd64(d + 8);
    v_bits = rd32(d + 16);
    omega_bits = rd32(d + 20);
    c->flags = rd16(d + 24);
    c->session = 0;
    c->source = 0;
    c->v_mps = f32_of(v_bits);
    c->omega_radps = f32_of(omega_bits);
    return check_fields(c, v_bits, omega_bits);
}

/* Version 2, 52 bytes: length, magic, version, MAC, reserved byte, then the fields. */
static carlink_verdict decode_v2(const carlink_state *s, const uint8_t *d, size_t len, carlink_command *c)
{
    uint8_t mac[32];
    uint32_t v_bits, omega_bits;
    if (len != CARLINK_V2_SIZE)
        return CARLINK_BAD_LENGTH;
    if (d[0] != 'T' || d[1] != 'F')
        return CARLINK_BAD_MAGIC;
    if (d[2] != 2)
        return CARLINK_BAD_VERSION;
    hmac_keyed(&s->inner, &s->outer, d, 36, mac);
    if (differ(mac, d + 36, CARLINK_MAC_BYTES))
        return CARLINK_BAD_MAC;
    if (d[5] != 0)
        return CARLINK_BAD_RESERVED;
    c->version = 2;
    c->car_id = d[3];
    c->source = d[4];
    c->flags = rd16(d + 6);
    c->session = rd64(d + 8);
    c->seq = rd32(d + 16);
    c->stamp_bits = rd64(d + 20);
    v_bits = rd32(d + 28);
    omega_bits = rd32(d + 32);
    c->v_mps = f32_of(v_bits);
    c->omega_radps = f32_of(omega_bits);
    return check_fields(c, v_bits, omega_bits);
}

/* ------------------------------------------------------------------------ the rules */

static int bit(const uint8_t *bits, uint8_t i) { return (bits[i >> 3] >> (i & 7u)) & 1; }
static void set_bit(uint8_t *bits, uint8_t i) { bits[i >> 3] = (uint8_t)(bits[i >> 3] | (1u << (i & 7u))); }
static void clear_bit(uint8_t *bits, uint8_t i) { bits[i >> 3] = (uint8_t)(bits[i >> 3] & ~(1u << (i & 7u))); }

int carlink_init(carlink_state *s, uint8_t car_id, const uint8_t *key, uint32_t watchdog_ms, uint32_t resync_ms)
{
    if (car_id == 0 || watchdog_ms == 0 || resync_ms <= watchdog_ms)
        return -1; /* a new sequence is adopted (version 1) only at a standstill */
    memset(s, 0, sizeof *s);
    s->car_id = car_id;
    s->watchdog_ms = watchdog_ms;
    s->resync_ms = resync_ms;
    if (key != NULL) {
        s->has_key = 1;
        hmac_key(&s->inner, &s->outer, key, CARLINK_KEY_BYTES);
    }
    return 0;
}

int carlink_any_e_stop(const carlink_state *s)
{
    unsigned i;
    for (i = 0; i < sizeof s->e_stop; i++)
        if (s->e_stop[i])
            return 1;
    return 0;
}

int carlink_e_stop_latched(const carlink_state *s, uint8_t source) { return bit(s->e_stop, source); }

/* Rules 6 and 8. Elapsed time in unsigned arithmetic: right across the clock's wrap. */
int carlink_motors(const carlink_state *s, uint32_t now_ms, float *v_mps, float *omega_radps)
{
    float v = 0.0f, omega = 0.0f;
    if (s->has_last && !carlink_any_e_stop(s) && !(s->last.flags & CARLINK_STOP)
        && (uint32_t)(now_ms - s->last_ms) < s->watchdog_ms) {
        v = s->last.v_mps;
        omega = s->last.omega_radps;
    }
    if (v_mps != NULL)
        *v_mps = v;
    if (omega_radps != NULL)
        *omega_radps = omega;
    return v == 0.0f && omega == 0.0f;
}

uint16_t carlink_car_state(const carlink_state *s, uint32_t now_ms)
{
    uint16_t state = carlink_any_e_stop(s) ? (uint16_t)CARLINK_STATE_E_STOP_LATCHED : (uint16_t)0;
    if (carlink_motors(s, now_ms, NULL, NULL))
        state = (uint16_t)(state | CARLINK_STATE_STOPPED);
    return state;
}

/* Rule 5 (version 1): serial-number arithmetic (RFC 1982); after resync_ms without an
 * accepted datagram, any seq (a restarted sender). */
static carlink_verdict sequence_ok(carlink_state *s, const carlink_command *c, uint32_t now_ms,
                                   carlink_result *r)
{
    uint32_t distance;
    if (!s->has_last)
        return CARLINK_ACCEPTED;
    distance = c->seq - s->last.seq;
    if (distance != 0 && distance < 0x80000000u)
        return CARLINK_ACCEPTED;
    if ((uint32_t)(now_ms - s->last_ms) >= s->resync_ms) {
        s->counters.resynced++;
        r->resynced = 1;
        return CARLINK_ACCEPTED;
    }
    if (c->seq == s->last.seq) {
        s->counters.repeated_seq++;
        return CARLINK_REPEATED_SEQ;
    }
    s->counters.stale_seq++;
    return CARLINK_STALE_SEQ;
}

/* Rule 4 (version 2): per source, the newest session only, and in it a larger seq. */
static carlink_verdict session_ok(carlink_state *s, const carlink_command *c, carlink_result *r)
{
    uint8_t src = c->source;
    if (!bit(s->session_known, src) || c->session > s->session[src]) {
        set_bit(s->session_known, src); /* a restarted sender: its older sessions are refused */
        s->session[src] = c->session;
        s->session_seq[src] = c->seq;
        s->counters.new_session++;
        r->new_session = 1;
        return CARLINK_ACCEPTED;
    }
    if (c->session < s->session[src]) {
        s->counters.old_session++;
        return CARLINK_OLD_SESSION;
    }
    if (c->seq <= s->session_seq[src]) {
        if (c->seq == s->session_seq[src]) {
            s->counters.repeated_seq++;
            return CARLINK_REPEATED_SEQ;
        }
        s->counters.stale_seq++;
        return CARLINK_STALE_SEQ;
    }
    s->session_seq[src] = c->seq;
    return CARLINK_ACCEPTED;
}

/* The answer to a PING (answer.py): the car's state after handling it, echoing the
 * PING's seq and stamp (version 2: its source and session too). */
static void build_answer(const carlink_state *s, const carlink_command *c, uint32_t now_ms, carlink_result *r)
{
    uint8_t *a = r->answer;
    uint16_t state = carlink_car_state(s, now_ms);
    a[0] = 'T';
    a[1] = 'A';
    a[3] = s->car_id;
    if (!s->has_key) {
        a[2] = 1;
        wr32(a + 4, c->seq);
        wr64(a + 8, c->stamp_bits);
        wr16(a + 16, state);
        wr32(a + 18, carlink_crc32(a, 18));
        r->answer_len = CARLINK_ANSWER_V1_SIZE;
    } else {
        uint8_t mac[32];
        a[2] = 2;
        a[4] = c->source;
        a[5] = 0;
        wr16(a + 6, state);
        wr64(a + 8, c->session);
        wr32(a + 16, c->seq);
        wr64(a + 20, c->stamp_bits);
        hmac_keyed(&s->inner, &s->outer, a, 28, mac);
        memcpy(a + 28, mac, CARLINK_MAC_BYTES);
        r->answer_len = CARLINK_ANSWER_V2_SIZE;
    }
}

carlink_verdict carlink_receive(carlink_state *s, const uint8_t *data, size_t len, uint32_t now_ms,
                                carlink_result *out)
{
    carlink_result scratch;
    carlink_result *r = out != NULL ? out : &scratch;
    carlink_command *c = &r->command;
    carlink_verdict v;

    memset(r, 0, sizeof *r);
    if (data == NULL)
        len = 0;
    /* Rule 1: decode (a car with a key speaks version 2 only, without one version 1). */
    v = s->has_key ? decode_v2(s, data, len, c) : decode_v1(data, len, c);
    if (v != CARLINK_ACCEPTED) {
        s->counters.decode_errors[v - CARLINK_FIRST_DECODE_ERROR]++;
        memset(c, 0, sizeof *c);
        return r->verdict = v;
    }
    if (c->car_id != s->car_id) {
        s->counters.wrong_car++;
        return r->verdict = CARLINK_WRONG_CAR;
    }
    /* Rule 2: E_STOP latches for its source, whatever its seq or session, touching
     * neither the sequence reference nor the watchdog; rule 3 still answers it. */
    if (c->flags & CARLINK_E_STOP) {
        set_bit(s->e_stop, c->source);
        s->counters.e_stops++;
        if (c->flags & CARLINK_PING) {
            s->counters.pings++;
            build_answer(s, c, now_ms, r);
        }
        return r->verdict = CARLINK_E_STOP_TAKEN;
    }
    /* Rule 3: a PING is answered and otherwise not applied. */
    if (c->flags & CARLINK_PING) {
        s->counters.pings++;
        build_answer(s, c, now_ms, r);
        return r->verdict = CARLINK_PING_ONLY;
    }
    v = s->has_key ? session_ok(s, c, r) : sequence_ok(s, c, now_ms, r);
    if (v != CARLINK_ACCEPTED)
        return r->verdict = v;
    /* Rule 7: only its own source's accepted RELEASE clears a latch. */
    if ((c->flags & CARLINK_RELEASE) && bit(s->e_stop, c->source))
        clear_bit(s->e_stop, c->source);
    s->last = *c;
    s->last_ms = now_ms;
    s->has_last = 1;
    s->counters.accepted++;
    return r->verdict = CARLINK_ACCEPTED;
}

const char *carlink_verdict_name(carlink_verdict verdict)
{
    static const char *const names[CARLINK_VERDICTS] = {
        "accepted", "e_stop", "ping", "wrong_car", "repeated_seq", "stale_seq", "old_session",
        "length", "magic", "version", "crc", "mac", "reserved", "car_id", "flags", "non_finite",
    };
    if ((unsigned)verdict >= (unsigned)CARLINK_VERDICTS)
        return NULL;
    return names[verdict];
}
