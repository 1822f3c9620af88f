/* Deterministic mutation fuzzing of the car-link core (tests only; built with
 * -fsanitize=address,undefined, which end the run at the first fault).
 *
 *   carlink_fuzz SEEDS KEYHEX INPUTS RNGSEED
 *
 * SEEDS holds valid datagrams, one hex line each. Every input is a seed with one to four
 * mutations (bit flips, byte values, special field values, cuts, extensions, splices),
 * half of them sealed again with a valid MAC or CRC so that the checks behind the MAC
 * are reached too. Each input goes to a version-2 car (with KEYHEX) and a version-1 car
 * at a time that moves on by 0 ms to seconds (and once across the u32 wrap). Checked on
 * every input: the verdict is one of the enum, an answer comes exactly for a PING and
 * verifies, the motors are finite and zero under an e-stop, and the counters add up.
 * Prints "inputs N" and, per car, the count of every verdict. */
#include "carlink.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_SEEDS 256
#define MAX_LEN 96

static uint8_t seeds[MAX_SEEDS][MAX_LEN];
static size_t seed_len[MAX_SEEDS];
static size_t n_seeds;
static uint64_t rng_state;

static uint32_t rnd(void)
{ /* xorshift64* */
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (uint32_t)((rng_state * 0x2545F4914F6CDD1DULL) >> 32);
}

static uint32_t below(uint32_t n) { return rnd() % n; }

static void fail(const char *what, unsigned long input)
{
    fprintf(stderr, "carlink_fuzz: input %lu: %s\n", input, what);
    exit(1);
}

static int hex_value(int ch)
{
    if (ch >= '0' && ch <= '9')
        return ch - '0';
    if (ch >= 'a' && ch <= 'f')
        return ch - 'a' + 10;
    return -1;
}

static size_t parse_hex(const char *text, uint8_t *out, size_t capacity)
{
    size_t n = 0;
    while (text[0] && text[1] && n < capacity) {
        int hi = hex_value(text[0]), lo = hex_value(text[1]);
        if (hi < 0 || lo < 0)
            break;
        out[n++] = (uint8_t)(hi * 16 + lo);
        text += 2;
    }
    return n;
}

static void put32(uint8_t *p, uint32_t v)
{
    unsigned i;
    for (i = 0; i < 4; i++)
        p[i] = (uint8_t)(v >> (8 * i));
}

static void mutate(uint8_t *d, size_t *len)
{
    static const uint32_t specials[] = {0x7FC00000u, 0x7F800000u, 0xFF800000u, 0x00000001u, 0x80000000u,
                                        0x7F7FFFFFu, 0u};
    uint32_t kind = below(9);
    size_t at = *len > 0 ? below((uint32_t)*len) : 0;
    switch (kind) {
    case 0: /* flip a bit */
        if (*len > 0)
            d[at] = (uint8_t)(d[at] ^ (1u << below(8)));
        break;
    case 1: /* a byte value */
        if (*len > 0)
            d[at] = (uint8_t)rnd();
        break;
    case 2: /* a special f32 in a float field (v2: 28, 32; v1: 16, 20) or a stamp's exponent */
        if (*len >= 36) {
            put32(d + (below(2) ? 28 : 32), specials[below(7)]);
            if (below(4) == 0)
                d[27] = (uint8_t)(d[27] | 0x7Fu), d[26] = (uint8_t)(d[26] | 0xF0u);
        } else if (*len >= 24) {
            put32(d + (below(2) ? 16 : 20), specials[below(7)]);
        }
        break;
    case 3: /* the header: car id, source, reserved byte, flags */
        if (*len >= 8)
            d[3 + below(5)] = (uint8_t)(below(3) == 0 ? 0u : rnd() & 0x1Fu);
        break;
    case 4: /* cut */
        *len = below((uint32_t)*len + 1);
        break;
    case 5: /* extend */
        while (*len < MAX_LEN && below(3) != 0)
            d[(*len)++] = (uint8_t)rnd();
        break;
    case 6: { /* splice from another seed */
        size_t other = below((uint32_t)n_seeds), i, n = seed_len[other];
        for (i = at; i < *len && i < n; i++)
            if (below(2))
                d[i] = seeds[other][i];
        break;
    }
    case 7: /* session or seq bytes (v2: 8..19) */
        if (*len >= 20)
            d[8 + below(12)] = (uint8_t)rnd();
        break;
    default: /* seq nearby */
        if (*len >= 20)
            d[16] = (uint8_t)(d[16] + below(5) - 2u);
        break;
    }
}

static void reseal(uint8_t *d, size_t len, const uint8_t *key)
{
    if (len == CARLINK_V2_SIZE) {
        uint8_t mac[32];
        carlink_hmac_sha256(key, CARLINK_KEY_BYTES, d, 36, mac);
        memcpy(d + 36, mac, CARLINK_MAC_BYTES);
    } else if (len == CARLINK_V1_SIZE) {
        put32(d + 26, carlink_crc32(d, 26));
    }
}

static unsigned long tally[2][CARLINK_VERDICTS], e_stop_pings[2], fed[2], total[2][CARLINK_VERDICTS];

static void check(carlink_state *s, int which, const uint8_t *d, size_t len, uint32_t now, const uint8_t *key,
                  unsigned long input)
{
    carlink_result r;
    carlink_verdict v = carlink_receive(s, d, len, now, &r);
    float mv, momega;
    uint32_t bits_v, bits_omega;
    unsigned long sum = 0;
    int stopped, i;
    const carlink_counters *c = &s->counters;

    if ((unsigned)v >= (unsigned)CARLINK_VERDICTS || v != r.verdict)
        fail("verdict outside the enum", input);
    fed[which]++;
    tally[which][v]++;
    total[which][v]++;
    if (v == CARLINK_E_STOP_TAKEN && (r.command.flags & CARLINK_PING))
        e_stop_pings[which]++;
    if ((v == CARLINK_PING_ONLY || (v == CARLINK_E_STOP_TAKEN && (r.command.flags & CARLINK_PING)))
        != (r.answer_len > 0))
        fail("an answer without a PING, or a PING without an answer", input);
    if (r.answer_len > 0) {
        if (s->has_key) {
            uint8_t mac[32];
            carlink_hmac_sha256(key, CARLINK_KEY_BYTES, r.answer, 28, mac);
            if (r.answer_len != CARLINK_ANSWER_V2_SIZE || memcmp(mac, r.answer + 28, CARLINK_MAC_BYTES) != 0)
                fail("a version-2 answer that does not verify", input);
        } else {
            uint32_t crc = carlink_crc32(r.answer, 18);
            if (r.answer_len != CARLINK_ANSWER_V1_SIZE || r.answer[18] != (uint8_t)crc
                || r.answer[21] != (uint8_t)(crc >> 24))
                fail("a version-1 answer with a bad CRC", input);
        }
        if (!(r.answer[6 + (s->has_key ? 0 : 10)] & CARLINK_STATE_E_STOP_LATCHED) != !carlink_any_e_stop(s))
            fail("the answer's latch bit is not the car's", input);
    }
    stopped = carlink_motors(s, now, &mv, &momega);
    memcpy(&bits_v, &mv, 4);
    memcpy(&bits_omega, &momega, 4);
    if (((bits_v >> 23) & 0xFFu) == 0xFFu || ((bits_omega >> 23) & 0xFFu) == 0xFFu)
        fail("non-finite motor command", input);
    if (carlink_any_e_stop(s) && !(stopped && mv == 0.0f && momega == 0.0f))
        fail("motors turn under a latched e-stop", input);
    if (v == CARLINK_E_STOP_TAKEN && !carlink_e_stop_latched(s, r.command.source))
        fail("an e-stop taken but not latched", input);
    sum = c->accepted + c->e_stops + (c->pings - e_stop_pings[which]) + c->wrong_car + c->stale_seq
          + c->repeated_seq + c->old_session;
    for (i = 0; i < (int)CARLINK_DECODE_ERRORS; i++)
        sum += c->decode_errors[i];
    if (sum != fed[which])
        fail("the counters do not add up to the inputs", input);
    if (c->accepted != tally[which][CARLINK_ACCEPTED] || c->e_stops != tally[which][CARLINK_E_STOP_TAKEN])
        fail("the counters disagree with the verdicts", input);
}

int main(int argc, char **argv)
{
    static carlink_state v2, v1;
    uint8_t key[CARLINK_KEY_BYTES], d[MAX_LEN];
    char line[512];
    unsigned long inputs, n;
    uint32_t now = 0;
    FILE *f;
    int which;
    size_t k;

    if (argc != 5 || parse_hex(argv[2], key, sizeof key) != sizeof key) {
        fprintf(stderr, "usage: carlink_fuzz SEEDS KEYHEX INPUTS RNGSEED\n");
        return 2;
    }
    inputs = strtoul(argv[3], NULL, 10);
    rng_state = strtoull(argv[4], NULL, 10) * 2654435761u + 1u;
    f = fopen(argv[1], "r");
    if (f == NULL)
        return 2;
    while (n_seeds < MAX_SEEDS && fgets(line, sizeof line, f) != NULL) {
        seed_len[n_seeds] = parse_hex(line, seeds[n_seeds], MAX_LEN);
        if (seed_len[n_seeds] > 0)
            n_seeds++;
    }
    fclose(f);
    if (n_seeds == 0 || carlink_init(&v2, 3, key, CARLINK_WATCHDOG_MS, CARLINK_RESYNC_MS) != 0
        || carlink_init(&v1, 3, NULL, CARLINK_WATCHDOG_MS, CARLINK_RESYNC_MS) != 0)
        return 2;

    for (n = 0; n < inputs; n++) {
        size_t seed = below((uint32_t)n_seeds), len = seed_len[seed];
        uint32_t mutations = below(5), m, step = below(16);
        memcpy(d, seeds[seed], len);
        for (m = 0; m < mutations; m++)
            mutate(d, &len);
        if (below(2))
            reseal(d, len, key);
        /* time: mostly a datagram's spacing, sometimes the watchdog, a resync, a jump */
        now += step < 10 ? below(25) : step < 14 ? below(400) : step < 15 ? 1000u + below(2000) : 0u;
        if (n == inputs / 2)
            now = 0xFFFFFF00u; /* cross the u32 wrap of the clock */
        check(&v2, 0, d, len, now, key, n);
        check(&v1, 1, d, len, now, key, n);
        if (below(2000) == 0) { /* a reboot now and then: sessions and latches forgotten */
            which = (int)below(2);
            if (carlink_init(which == 0 ? &v2 : &v1, 3, which == 0 ? key : NULL, CARLINK_WATCHDOG_MS,
                             CARLINK_RESYNC_MS) != 0)
                return 2;
            memset(tally[which], 0, sizeof tally[which]);
            e_stop_pings[which] = fed[which] = 0;
        }
    }
    printf("inputs %lu\n", inputs);
    for (which = 0; which < 2; which++)
        for (k = 0; k < CARLINK_VERDICTS; k++)
            printf("v%d %s %lu\n", 2 - which, carlink_verdict_name((carlink_verdict)k), total[which][k]);
    return 0;
}
