/*
 * carlink_posix.c -- a car on a PC: the car-link core (carlink.c) behind a UDP socket.
 *
 *   carlink_posix --car ID [--bind HOST:PORT] [--key FILE] [--watchdog-ms MS] [--verbose]
 *
 * Binds HOST:PORT (default 0.0.0.0:9000, the lab's car port; "udp://HOST:PORT" as in a
 * fleet config works too; port 0 picks a free one), speaks version 2 with the 32-byte
 * key in FILE (64 hex digits, whitespace ignored: a car's link_key_file) or version 1
 * without --key, answers every PING from the socket it arrived on, and prints what its
 * motors would do whenever that changes, and every e-stop latched or released. First
 * line: "carlink: car ID, version V, listening on HOST:PORT". SIGINT or SIGTERM end it
 * with the counters; exit status 0, or 2 for a usage or key-file error.
 */
#define _POSIX_C_SOURCE 200809L

#include "carlink.h"

#include <errno.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <time.h>
#include <unistd.h>
#include <arpa/inet.h>

#define TICK_MS 5 /* how often the motors are looked at without a datagram */

static volatile sig_atomic_t halted = 0;

static void on_signal(int signum)
{
    (void)signum;
    halted = 1;
}

static uint32_t now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint32_t)((uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u);
}

static double stamp_s(uint64_t bits)
{
    double d;
    memcpy(&d, &bits, sizeof d);
    return d;
}

static int usage(const char *why)
{
    fprintf(stderr, "carlink_posix: %s\nusage: carlink_posix --car ID [--bind HOST:PORT] [--key FILE] "
                    "[--watchdog-ms MS] [--verbose]\n", why);
    return 2;
}

static int hex_digit(int ch)
{
    if (ch >= '0' && ch <= '9')
        return ch - '0';
    if (ch >= 'a' && ch <= 'f')
        return ch - 'a' + 10;
    if (ch >= 'A' && ch <= 'F')
        return ch - 'A' + 10;
    return -1;
}

/* A key file as bridge/carlink/keys.py reads it: 64 hex digits, whitespace ignored. */
static int read_key(const char *path, uint8_t key[CARLINK_KEY_BYTES])
{
    char text[4096];
    size_t len, i, digits = 0;
    struct stat st;
    FILE *f = fopen(path, "r");
    if (f == NULL) {
        fprintf(stderr, "carlink_posix: cannot read the key file %s: %s\n", path, strerror(errno));
        return -1;
    }
    len = fread(text, 1, sizeof text, f);
    if (fstat(fileno(f), &st) == 0 && (st.st_mode & (S_IRWXG | S_IRWXO)))
        fprintf(stderr, "carlink_posix: warning: the key file %s is readable by others (chmod 600 it)\n", path);
    fclose(f);
    for (i = 0; i < len; i++) {
        int ch = (unsigned char)text[i], value;
        if (ch == ' ' || ch == '\t' || ch == '\n' || ch == '\r' || ch == '\v' || ch == '\f')
            continue;
        value = hex_digit(ch);
        if (value < 0 || digits >= 2 * CARLINK_KEY_BYTES || len == sizeof text) {
            fprintf(stderr, "carlink_posix: %s: a car-link key is %u hexadecimal digits\n", path,
                    2 * CARLINK_KEY_BYTES);
            return -1;
        }
        if (digits % 2 == 0)
            key[digits / 2] = (uint8_t)(value << 4);
        else
            key[digits / 2] = (uint8_t)(key[digits / 2] | value);
        digits++;
    }
    if (digits != 2 * CARLINK_KEY_BYTES) {
        fprintf(stderr, "carlink_posix: %s: a car-link key is %u bytes (%u hex digits), got %lu digits\n", path,
                CARLINK_KEY_BYTES, 2 * CARLINK_KEY_BYTES, (unsigned long)digits);
        return -1;
    }
    return 0;
}

/* HOST:PORT or udp://HOST:PORT (IPv6 in brackets); IPv4 preferred, as the Python side. */
static int bind_socket(const char *address)
{
    char host[256];
    const char *colon, *port;
    size_t host_len;
    struct addrinfo hints, *found = NULL, *ai;
    int fd = -1, families[2] = {AF_INET, AF_UNSPEC}, k;

    if (strncmp(address, "udp://", 6) == 0)
        address += 6;
    colon = strrchr(address, ':');
    if (colon == NULL || colon == address || colon[1] == '\0')
        return usage("--bind takes HOST:PORT"), -1;
    port = colon + 1;
    host_len = (size_t)(colon - address);
    if (address[0] == '[' && host_len >= 2 && address[host_len - 1] == ']') {
        address++;
        host_len -= 2;
    }
    if (host_len >= sizeof host)
        return usage("--bind: host name too long"), -1;
    memcpy(host, address, host_len);
    host[host_len] = '\0';
    for (k = 0; k < 2 && found == NULL; k++) {
        memset(&hints, 0, sizeof hints);
        hints.ai_family = families[k];
        hints.ai_socktype = SOCK_DGRAM;
        hints.ai_flags = AI_PASSIVE;
        if (getaddrinfo(host, port, &hints, &found) != 0)
            found = NULL;
    }
    if (found == NULL) {
        fprintf(stderr, "carlink_posix: cannot resolve %s:%s\n", host, port);
        return -1;
    }
    for (ai = found; ai != NULL; ai = ai->ai_next) {
        fd = socket(ai->ai_family, ai->ai_socktype, ai->ai_protocol);
        if (fd < 0)
            continue;
        if (bind(fd, ai->ai_addr, ai->ai_addrlen) == 0)
            break;
        fprintf(stderr, "carlink_posix: cannot bind %s:%s: %s\n", host, port, strerror(errno));
        close(fd);
        fd = -1;
    }
    freeaddrinfo(found);
    return fd;
}

static void print_address(const char *what, const struct sockaddr_storage *address)
{
    char text[INET6_ADDRSTRLEN] = "?";
    unsigned port = 0;
    if (address->ss_family == AF_INET) {
        const struct sockaddr_in *in = (const struct sockaddr_in *)(const void *)address;
        inet_ntop(AF_INET, &in->sin_addr, text, sizeof text);
        port = ntohs(in->sin_port);
    } else if (address->ss_family == AF_INET6) {
        const struct sockaddr_in6 *in6 = (const struct sockaddr_in6 *)(const void *)address;
        inet_ntop(AF_INET6, &in6->sin6_addr, text, sizeof text);
        port = ntohs(in6->sin6_port);
    }
    printf("%s%s:%u", what, text, port);
}

static void print_counters(const carlink_counters *c)
{
    int i;
    printf("carlink: accepted %lu, resynced %lu, e-stops %lu, pings %lu, wrong car %lu, stale %lu, repeated %lu, "
           "new sessions %lu, old sessions %lu", (unsigned long)c->accepted, (unsigned long)c->resynced,
           (unsigned long)c->e_stops, (unsigned long)c->pings, (unsigned long)c->wrong_car,
           (unsigned long)c->stale_seq, (unsigned long)c->repeated_seq, (unsigned long)c->new_session,
           (unsigned long)c->old_session);
    for (i = 0; i < (int)CARLINK_DECODE_ERRORS; i++)
        if (c->decode_errors[i])
            printf(", %s %lu", carlink_verdict_name((carlink_verdict)(CARLINK_FIRST_DECODE_ERROR + i)),
                   (unsigned long)c->decode_errors[i]);
    printf("\n");
}

int main(int argc, char **argv)
{
    static carlink_state car;
    const char *bind_to = "0.0.0.0:9000", *key_file = NULL;
    long car_id = 0, watchdog_ms = CARLINK_WATCHDOG_MS;
    int verbose = 0, fd, i;
    uint8_t key[CARLINK_KEY_BYTES];
    struct sockaddr_storage local;
    socklen_t local_len = sizeof local;
    struct sigaction action;
    float shown_v = 0.0f, shown_omega = 0.0f;
    uint8_t shown_latch[CARLINK_SOURCES / 8];

    for (i = 1; i < argc; i++) {
        const char *arg = argv[i], *value = i + 1 < argc ? argv[i + 1] : NULL;
        char *end = NULL;
        if (strcmp(arg, "--verbose") == 0) {
            verbose = 1;
            continue;
        }
        if (value == NULL)
            return usage("an option lacks its value");
        i++;
        if (strcmp(arg, "--car") == 0) {
            car_id = strtol(value, &end, 10);
            if (*end != '\0' || car_id < 1 || car_id > 255)
                return usage("--car takes 1..255");
        } else if (strcmp(arg, "--bind") == 0) {
            bind_to = value;
        } else if (strcmp(arg, "--key") == 0) {
            key_file = value;
        } else if (strcmp(arg, "--watchdog-ms") == 0) {
            watchdog_ms = strtol(value, &end, 10);
            if (*end != '\0' || watchdog_ms < 1 || watchdog_ms >= (long)CARLINK_RESYNC_MS)
                return usage("--watchdog-ms takes 1..999");
        } else {
            return usage("unknown option");
        }
    }
    if (car_id == 0)
        return usage("--car is required");
    if (key_file != NULL && read_key(key_file, key) != 0)
        return 2;
    if (carlink_init(&car, (uint8_t)car_id, key_file != NULL ? key : NULL, (uint32_t)watchdog_ms,
                     CARLINK_RESYNC_MS) != 0)
        return usage("bad parameters");
    memset(key, 0, sizeof key);

    setvbuf(stdout, NULL, _IOLBF, 0);
    memset(&action, 0, sizeof action);
    action.sa_handler = on_signal;
    sigaction(SIGINT, &action, NULL);
    sigaction(SIGTERM, &action, NULL);

    fd = bind_socket(bind_to);
    if (fd < 0)
        return 2;
    getsockname(fd, (struct sockaddr *)&local, &local_len);
    printf("carlink: car %ld, version %d, ", car_id, key_file != NULL ? 2 : 1);
    print_address("listening on ", &local);
    printf("\n");
    memset(shown_latch, 0, sizeof shown_latch);

    while (!halted) {
        struct pollfd pfd;
        uint32_t now;
        float v, omega;
        unsigned source;
        pfd.fd = fd;
        pfd.events = POLLIN;
        pfd.revents = 0;
        if (poll(&pfd, 1, TICK_MS) < 0 && errno != EINTR)
            break;
        now = now_ms();
        if (pfd.revents & POLLIN) {
            uint8_t buffer[2048]; /* larger than a datagram: an oversized one is seen, not cut */
            struct sockaddr_storage from;
            socklen_t from_len = sizeof from;
            carlink_result result;
            ssize_t got = recvfrom(fd, buffer, sizeof buffer, 0, (struct sockaddr *)&from, &from_len);
            if (got >= 0) {
                now = now_ms();
                carlink_receive(&car, buffer, (size_t)got, now, &result);
                if (result.answer_len > 0
                    && sendto(fd, result.answer, result.answer_len, 0, (struct sockaddr *)&from, from_len) < 0)
                    fprintf(stderr, "carlink_posix: answer failed: %s\n", strerror(errno));
                if (verbose) {
                    printf("%u.%03u %s source %u seq %lu stamp %.6f from ", (unsigned)(now / 1000),
                           (unsigned)(now % 1000), carlink_verdict_name(result.verdict), result.command.source,
                           (unsigned long)result.command.seq, stamp_s(result.command.stamp_bits));
                    print_address("", &from);
                    printf("\n");
                }
            }
        }
        for (source = 0; source < CARLINK_SOURCES; source++) {
            int latched = carlink_e_stop_latched(&car, (uint8_t)source);
            if (latched != ((shown_latch[source / 8] >> (source % 8)) & 1)) {
                printf("%u.%03u e-stop %s by source %u\n", (unsigned)(now / 1000), (unsigned)(now % 1000),
                       latched ? "latched" : "released", source);
                shown_latch[source / 8] = (uint8_t)(shown_latch[source / 8] ^ (1u << (source % 8)));
            }
        }
        carlink_motors(&car, now, &v, &omega);
        if (v != shown_v || omega != shown_omega) {
            printf("%u.%03u motors v %.3f m/s omega %.3f rad/s\n", (unsigned)(now / 1000),
                   (unsigned)(now % 1000), (double)v, (double)omega);
            shown_v = v;
            shown_omega = omega;
        }
    }
    print_counters(&car.counters);
    return 0;
}
