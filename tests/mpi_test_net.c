/* The MPI renderer's transport (apps/mpi/mpi_net.c) without MPI running: frames of every size
 * (empty, small, a borrowed 3 MiB payload) arrive whole and in order through non-blocking sockets
 * whose buffers are far smaller than the frames; bytes that are not a frame, a frame above the
 * limit and a closed peer end the connection with a message; a silent peer is a time-out, not a
 * hang; rank 0's listening socket takes a connection at the address its rendezvous names. */
#include <arpa/inet.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include "mpi_render.h"
#include "rp_test.h"

static void pair(mpir_conn *a, mpir_conn *b, uint64_t max_in) {
    int sv[2] = {-1, -1};
    CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0);
    int small = 4096; /* so that frames are cut into many partial sends and reads */
    setsockopt(sv[0], SOL_SOCKET, SO_SNDBUF, &small, sizeof small);
    setsockopt(sv[1], SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
    mpir_conn_init(a, sv[0], max_in);
    mpir_conn_init(b, sv[1], max_in);
}

/* Flushes a while reading b until b has a frame; the frame's type, or -1 on failure. */
static int pump(mpir_conn *a, mpir_conn *b) {
    for (int spins = 0; spins < 1000000; spins++) {
        if (mpir_conn_flush(a) < 0) return -1;
        int rc = mpir_conn_read(b);
        if (rc < 0) return -1;
        if (rc > 0) return (int)b->hdr.type;
    }
    return -1;
}

int main(void) {
    mpir_conn a, b;
    pair(&a, &b, (uint64_t)1 << 24);
    size_t big = 3u << 20;
    uint8_t *scene = malloc(big), *small = malloc(1000);
    for (size_t i = 0; i < big; i++) scene[i] = (uint8_t)(i * 7u + (i >> 13));
    for (size_t i = 0; i < 1000; i++) small[i] = (uint8_t)(255 - i);
    /* a borrowed payload first (the scene), then nothing may be queued until it is sent */
    CHECK(mpir_conn_queue_borrowed(&a, MSG_SCENE, scene, big));
    CHECK(!mpir_conn_queue(&a, MSG_JOB, small, 10, NULL, 0));
    CHECK(pump(&a, &b) == MSG_SCENE && b.hdr.bytes == big && memcmp(b.in, scene, big) == 0);
    mpir_conn_next(&b);
    CHECK(!mpir_conn_pending(&a));
    /* then frames of two parts, and an empty one, in order */
    CHECK(mpir_conn_queue(&a, MSG_RESULT, small, 100, small + 100, 900));
    CHECK(mpir_conn_queue(&a, MSG_READY, NULL, 0, NULL, 0));
    CHECK(mpir_conn_queue(&a, MSG_JOB, small, 7, NULL, 0));
    CHECK(pump(&a, &b) == MSG_RESULT && b.hdr.bytes == 1000 && memcmp(b.in, small, 1000) == 0);
    mpir_conn_next(&b);
    CHECK(pump(&a, &b) == MSG_READY && b.hdr.bytes == 0);
    mpir_conn_next(&b);
    CHECK(pump(&a, &b) == MSG_JOB && b.hdr.bytes == 7 && memcmp(b.in, small, 7) == 0);
    mpir_conn_next(&b);
    uint64_t header = sizeof(net_header);
    CHECKF(a.bytes_out == b.bytes_in && b.bytes_in == 4 * header + big + 1007, "bytes %llu %llu",
           (unsigned long long)a.bytes_out, (unsigned long long)b.bytes_in);
    /* silence: a time-out after the idle limit, not a hang */
    CHECK(mpir_conn_recv_idle(&b, 0.3) == 0);
    /* the peer closes: the end of stream is an error with a message */
    mpir_conn_close(&a);
    CHECK(mpir_conn_recv_idle(&b, 5.0) < 0 && strstr(b.err, "closed"));
    mpir_conn_close(&b);

    /* bytes that are not a frame */
    pair(&a, &b, 1 << 20);
    net_header bad = {.type = MSG_JOB, .check = 12345u, .bytes = 4};
    CHECK(write(a.fd, &bad, sizeof bad) == (ssize_t)sizeof bad);
    CHECK(mpir_conn_recv_idle(&b, 5.0) < 0 && strstr(b.err, "not a raypack frame"));
    mpir_conn_close(&a);
    mpir_conn_close(&b);
    /* a frame above the limit is refused before its payload is allocated */
    pair(&a, &b, 1000);
    CHECK(mpir_conn_queue(&a, MSG_RESULT, small, 1000, small, 1));
    CHECK(pump(&a, &b) < 0 && strstr(b.err, "1001-byte frame"));
    /* sending to a closed peer fails (no SIGPIPE) */
    mpir_conn_close(&b);
    CHECK(mpir_conn_queue(&a, MSG_RESULT, scene, big, NULL, 0));
    CHECK(mpir_conn_send_idle(&a, 5.0) < 0);
    mpir_conn_close(&a);

    /* rank 0's listening socket and its rendezvous: loopback is named last and takes a client */
    rendezvous_msg rv;
    char err[256] = "";
    int lfd = mpir_listen(&rv, err, sizeof err);
    CHECKF(lfd >= 0, "%s", err);
    if (lfd >= 0) {
        CHECK(rv.magic == MPIR_MAGIC && rv.protocol == MPIR_PROTOCOL && rv.port > 0 && rv.addr_count >= 1 &&
              rv.addr_count <= 8 && (ntohl(rv.addr[rv.addr_count - 1]) >> 24) == 127);
        int cfd = mpir_connect(&rv, mpir_now_s() + 10.0, err, sizeof err);
        CHECKF(cfd >= 0, "%s", err);
        struct pollfd p = {.fd = lfd, .events = POLLIN};
        CHECK(poll(&p, 1, 5000) == 1);
        int sfd = accept(lfd, NULL, NULL);
        CHECK(sfd >= 0);
        if (cfd >= 0 && sfd >= 0) {
            mpir_conn_init(&a, cfd, 1 << 20);
            mpir_conn_init(&b, sfd, 1 << 20);
            hello_msg h = {.magic = MPIR_MAGIC, .token = rv.token, .rank = 3};
            CHECK(mpir_conn_queue(&a, MSG_HELLO, &h, sizeof h, NULL, 0));
            CHECK(pump(&a, &b) == MSG_HELLO && b.hdr.bytes == sizeof h && memcmp(b.in, &h, sizeof h) == 0);
            mpir_conn_close(&a);
            mpir_conn_close(&b);
        }
        close(lfd);
        /* nobody listens there any more: a clear error, within the deadline */
        double t0 = mpir_now_s();
        CHECK(mpir_connect(&rv, mpir_now_s() + 5.0, err, sizeof err) < 0 && strstr(err, "cannot connect to rank 0"));
        CHECK(mpir_now_s() - t0 < 20.0);
    }
    free(scene);
    free(small);
    return RP_TEST_END();
}
