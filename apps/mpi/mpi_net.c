/* Transfers that never block for good: every send, receive and broadcast is non-blocking and
 * polled against a deadline, so a dead or silent peer is a time-out, not a hang. */
#include <errno.h>
#include <math.h>
#include <mpi.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <unistd.h>

#include "cli.h"
#include "mpi_render.h"

/* CPU time of this process, all threads, in milliseconds. */
double mpir_cpu_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

void mpir_sleep_us(long us) {
    struct timespec ts = {.tv_sec = us / 1000000, .tv_nsec = (us % 1000000) * 1000};
    nanosleep(&ts, NULL);
}

/* Test hooks for the fault tests (tests/mpi_test_render.c): RAYPACK_MPI_TEST_<NAME>=RANK[:VALUE] makes that
 * rank misbehave; returns VALUE (1 without one) for this rank, else 0. */
long mpir_test_hook(const char *name, int rank) {
    char var[64];
    snprintf(var, sizeof var, "RAYPACK_MPI_TEST_%s", name);
    const char *v = getenv(var);
    if (!v) return 0;
    char *end;
    long r = strtol(v, &end, 10);
    if (end == v || r != rank) return 0;
    return *end == ':' ? strtol(end + 1, NULL, 10) : 1;
}

/* Waits for a non-blocking request until deadline (MPI_Wtime seconds); false on time-out. */
bool mpir_wait_until(MPI_Request *req, double deadline) {
    for (;;) {
        int done = 0;
        if (MPI_Test(req, &done, MPI_STATUS_IGNORE) != MPI_SUCCESS) return false;
        if (done) return true;
        if (MPI_Wtime() > deadline) return false;
        mpir_sleep_us(100);
    }
}

/* Blocking-style send that gives up at deadline instead of hanging on a dead peer. */
bool mpir_send_until(const void *buf, size_t bytes, int dest, int tag, double deadline) {
    MPI_Request req;
    if (MPI_Isend(buf, (int)bytes, MPI_BYTE, dest, tag, MPI_COMM_WORLD, &req) != MPI_SUCCESS) return false;
    return mpir_wait_until(&req, deadline);
}

/* Waits for a message with tag from src (or any) until deadline; fills status. */
bool mpir_probe_until(int src, int tag, double deadline, MPI_Status *st) {
    for (;;) {
        int flag = 0;
        if (MPI_Iprobe(src, tag, MPI_COMM_WORLD, &flag, st) != MPI_SUCCESS) return false;
        if (flag) return true;
        if (MPI_Wtime() > deadline) return false;
        mpir_sleep_us(100);
    }
}

/* A broadcast from rank 0 that times out: chunks below INT_MAX bytes, each an MPI_Ibcast. */
bool mpir_bcast_until(void *buf, size_t bytes, double deadline) {
    const size_t chunk = (size_t)1 << 30;
    for (size_t off = 0; off < bytes; off += chunk) {
        size_t n = bytes - off < chunk ? bytes - off : chunk;
        MPI_Request req;
        if (MPI_Ibcast((uint8_t *)buf + off, (int)n, MPI_BYTE, 0, MPI_COMM_WORLD, &req) != MPI_SUCCESS) return false;
        if (!mpir_wait_until(&req, deadline)) return false;
    }
    return true;
}
