/* A simulated board for mcu_example.c (tests only): the hooks the example declares, fed
 * from stdin and reported on stdout.
 *
 * Each input line is "MS" or "MS HEX": set the clock to MS, queue the datagram HEX (if
 * any), call car_link_poll(). Output lines: "motors V OMEGA" whenever motors_set() is
 * told something new, "answer HEX" for radio_send(), "log WHAT VALUE" for board_log(). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "carlink.h"

struct radio_peer {
    uint32_t ip;
    uint16_t port;
};

int car_link_setup(void);
void car_link_poll(void);
uint32_t board_millis(void);
int board_car_id(void);
int board_link_key(uint8_t key[32]);
size_t radio_receive(uint8_t *buffer, size_t capacity, struct radio_peer *from);
void radio_send(const uint8_t *data, size_t len, const struct radio_peer *to);
void motors_set(float v_mps, float omega_radps);
void board_log(const char *what, unsigned value);

static uint32_t clock_ms;
static uint8_t queued[128];
static size_t queued_len;
static float last_v = -1.0f, last_omega = -1.0f;

uint32_t board_millis(void) { return clock_ms; }

int board_car_id(void) { return 3; }

int board_link_key(uint8_t key[32])
{
    unsigned i;
    for (i = 0; i < 32; i++)
        key[i] = (uint8_t)i; /* the codec's worked example's key: 00 01 .. 1f */
    return 0;
}

size_t radio_receive(uint8_t *buffer, size_t capacity, struct radio_peer *from)
{
    size_t len = queued_len < capacity ? queued_len : capacity;
    memcpy(buffer, queued, len);
    queued_len = 0;
    from->ip = 0x7F000001u;
    from->port = 9000;
    return len;
}

void radio_send(const uint8_t *data, size_t len, const struct radio_peer *to)
{
    size_t i;
    if (to->ip != 0x7F000001u || to->port != 9000)
        printf("answer to the wrong peer\n");
    printf("answer ");
    for (i = 0; i < len; i++)
        printf("%02x", data[i]);
    printf("\n");
}

void motors_set(float v_mps, float omega_radps)
{
    if (v_mps != last_v || omega_radps != last_omega)
        printf("motors %.9g %.9g\n", (double)v_mps, (double)omega_radps);
    last_v = v_mps;
    last_omega = omega_radps;
}

void board_log(const char *what, unsigned value) { printf("log %s %u\n", what, value); }

int main(void)
{
    char line[512];
    if (car_link_setup() != 0)
        return 1;
    while (fgets(line, sizeof line, stdin) != NULL) {
        char *rest;
        size_t n = 0;
        clock_ms = (uint32_t)strtoul(line, &rest, 10);
        while (*rest == ' ')
            rest++;
        while (rest[0] && rest[1] && rest[0] != '\n' && n < sizeof queued) {
            unsigned byte;
            if (sscanf(rest, "%2x", &byte) != 1)
                break;
            queued[n++] = (uint8_t)byte;
            rest += 2;
        }
        queued_len = n;
        car_link_poll();
    }
    return 0;
}
