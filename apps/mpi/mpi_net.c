/* The transport: MPI only starts the ranks and tells each client rank 0's TCP address; scenes,
 * tiles and results travel as frames on one TCP connection per client, non-blocking and polled
 * against deadlines. A client's death is then an end of stream on rank 0 (or, for a client that
 * hangs, silence past the time-out), never a wait inside MPI's transport: Open MPI 4.1 has no
 * ULFM, and a peer killed while one of its messages was in flight could leave rank 0 stuck there. */
#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <ifaddrs.h>
#include <mpi.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "mpi_render.h"

double mpir_now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

double mpir_cpu_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

void mpir_sleep_us(long us) {
    struct timespec ts = {.tv_sec = us / 1000000, .tv_nsec = (us % 1000000) * 1000};
    nanosleep(&ts, NULL);
}

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

bool mpir_wait_until(MPI_Request *req, double deadline) {
    for (;;) {
        int done = 0;
        if (MPI_Test(req, &done, MPI_STATUS_IGNORE) != MPI_SUCCESS) return false;
        if (done) return true;
        if (mpir_now_s() > deadline) return false;
        mpir_sleep_us(1000);
    }
}

static void set_nonblocking(int fd) {
    int fl = fcntl(fd, F_GETFL, 0);
    if (fl >= 0) fcntl(fd, F_SETFL, fl | O_NONBLOCK);
    int one = 1;
    /* jobs are small frames that must not wait for Nagle's timer */
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
}

int mpir_listen(rendezvous_msg *rv, char *err, size_t err_size) {
    memset(rv, 0, sizeof *rv);
    rv->magic = MPIR_MAGIC;
    rv->protocol = MPIR_PROTOCOL;
    if (getrandom(&rv->token, sizeof rv->token, 0) != (ssize_t)sizeof rv->token)
        rv->token = ((uint64_t)getpid() << 32) ^ (uint64_t)(mpir_now_s() * 1e9);
    gethostname(rv->host, sizeof rv->host - 1);
    int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0) {
        snprintf(err, err_size, "cannot open a TCP socket: %s", strerror(errno));
        return -1;
    }
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_ANY), .sin_port = 0};
    socklen_t len = sizeof a;
    if (bind(fd, (struct sockaddr *)&a, sizeof a) != 0 || listen(fd, 256) != 0 ||
        getsockname(fd, (struct sockaddr *)&a, &len) != 0) {
        snprintf(err, err_size, "cannot listen on a TCP port: %s", strerror(errno));
        close(fd);
        return -1;
    }
    set_nonblocking(fd);
    rv->port = ntohs(a.sin_port);
    /* every IPv4 address of this host, loopback last (it reaches rank 0 only from its own host) */
    struct ifaddrs *ifs = NULL;
    uint32_t loop = htonl(INADDR_LOOPBACK);
    if (getifaddrs(&ifs) == 0) {
        for (struct ifaddrs *i = ifs; i && rv->addr_count < 7; i = i->ifa_next) {
            if (!i->ifa_addr || i->ifa_addr->sa_family != AF_INET) continue;
            uint32_t ip = ((struct sockaddr_in *)i->ifa_addr)->sin_addr.s_addr;
            if ((ntohl(ip) >> 24) != 127) rv->addr[rv->addr_count++] = ip;
        }
        freeifaddrs(ifs);
    }
    rv->addr[rv->addr_count++] = loop;
    return fd;
}

int mpir_connect(const rendezvous_msg *rv, double deadline, char *err, size_t err_size) {
    char host[64] = "";
    gethostname(host, sizeof host - 1);
    bool same_host = strncmp(host, rv->host, sizeof host) == 0;
    snprintf(err, err_size, "rank 0 (%s) named no address", rv->host);
    uint32_t n = rv->addr_count < 8 ? rv->addr_count : 8;
    /* In rank 0's order (loopback last, and only from its own host): a local address of this host
     * is routed through loopback anyway. */
    for (uint32_t k = 0; k < n; k++) {
        if ((ntohl(rv->addr[k]) >> 24) == 127 && !same_host) continue;
        int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        if (fd < 0) continue;
        set_nonblocking(fd);
        struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = rv->addr[k],
                                .sin_port = htons((uint16_t)rv->port)};
        int rc = connect(fd, (struct sockaddr *)&a, sizeof a);
        if (rc != 0 && errno == EINPROGRESS) {
            struct pollfd p = {.fd = fd, .events = POLLOUT};
            double left = deadline - mpir_now_s();
            int ms = left > 3.0 ? 3000 : (left > 0.0 ? (int)(left * 1e3) + 1 : 0);
            int so = ETIMEDOUT;
            socklen_t sl = sizeof so;
            if (poll(&p, 1, ms) == 1) getsockopt(fd, SOL_SOCKET, SO_ERROR, &so, &sl);
            rc = so == 0 ? 0 : -1;
            errno = so;
        }
        if (rc == 0) return fd;
        char ip[INET_ADDRSTRLEN] = "";
        inet_ntop(AF_INET, &rv->addr[k], ip, sizeof ip);
        snprintf(err, err_size, "cannot connect to rank 0 at %s:%u (%s): %s", ip, rv->port, rv->host,
                 strerror(errno));
        close(fd);
    }
    return -1;
}

void mpir_conn_init(mpir_conn *c, int fd, uint64_t max_in) {
    memset(c, 0, sizeof *c);
    c->fd = fd;
    c->max_in = max_in;
    set_nonblocking(fd);
}

void mpir_conn_close(mpir_conn *c) {
    if (c->fd >= 0) close(c->fd);
    c->fd = -1;
    free(c->out);
    free(c->in);
    c->out = c->in = NULL;
    c->out_len = c->out_off = c->out_cap = c->in_cap = c->in_have = c->hdr_have = 0;
    c->borrowed = NULL;
    c->borrowed_len = c->borrowed_off = 0;
}

static bool reserve_out(mpir_conn *c, size_t more) {
    if (c->out_off == c->out_len) c->out_off = c->out_len = 0;
    if (c->out_len + more <= c->out_cap) return true;
    if (c->out_off > 0) {
        memmove(c->out, c->out + c->out_off, c->out_len - c->out_off);
        c->out_len -= c->out_off;
        c->out_off = 0;
        if (c->out_len + more <= c->out_cap) return true;
    }
    size_t cap = c->out_cap ? c->out_cap : 4096;
    while (cap < c->out_len + more) cap *= 2;
    uint8_t *p = realloc(c->out, cap);
    if (!p) return false;
    c->out = p;
    c->out_cap = cap;
    return true;
}

static bool queue_header(mpir_conn *c, uint32_t type, uint64_t bytes, size_t more) {
    net_header h = {.type = type, .check = MPIR_MAGIC ^ type, .bytes = bytes};
    if (c->borrowed || !reserve_out(c, sizeof h + more)) return false; /* nothing may overtake a borrowed payload */
    memcpy(c->out + c->out_len, &h, sizeof h);
    c->out_len += sizeof h;
    return true;
}

bool mpir_conn_queue(mpir_conn *c, uint32_t type, const void *a, size_t an, const void *b, size_t bn) {
    if (!queue_header(c, type, (uint64_t)(an + bn), an + bn)) return false;
    if (an) memcpy(c->out + c->out_len, a, an);
    if (bn) memcpy(c->out + c->out_len + an, b, bn);
    c->out_len += an + bn;
    return true;
}

bool mpir_conn_queue_borrowed(mpir_conn *c, uint32_t type, const void *buf, size_t n) {
    if (!queue_header(c, type, (uint64_t)n, 0)) return false;
    c->borrowed = buf;
    c->borrowed_len = n;
    c->borrowed_off = 0;
    return true;
}

bool mpir_conn_pending(const mpir_conn *c) { return c->out_off < c->out_len || c->borrowed_off < c->borrowed_len; }

static int fail(mpir_conn *c, const char *what, int e) {
    snprintf(c->err, sizeof c->err, "%s", e ? strerror(e) : what);
    return -1;
}

int mpir_conn_flush(mpir_conn *c) {
    while (mpir_conn_pending(c)) {
        bool own = c->out_off < c->out_len;
        const uint8_t *p = own ? c->out + c->out_off : c->borrowed + c->borrowed_off;
        size_t n = own ? c->out_len - c->out_off : c->borrowed_len - c->borrowed_off;
        ssize_t k = send(c->fd, p, n, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (k < 0) {
            if (errno == EINTR) continue;
            if (errno == EAGAIN || errno == EWOULDBLOCK) return 0;
            return fail(c, NULL, errno);
        }
        c->bytes_out += (uint64_t)k;
        if (own) c->out_off += (size_t)k;
        else c->borrowed_off += (size_t)k;
    }
    if (c->borrowed) {
        c->borrowed = NULL;
        c->borrowed_len = c->borrowed_off = 0;
    }
    return 1;
}

int mpir_conn_read(mpir_conn *c) {
    for (;;) {
        bool in_header = c->hdr_have < sizeof c->hdr;
        if (!in_header && c->in_have == c->hdr.bytes) return 1;
        uint8_t *p = in_header ? (uint8_t *)&c->hdr + c->hdr_have : c->in + c->in_have;
        size_t n = in_header ? sizeof c->hdr - c->hdr_have : (size_t)c->hdr.bytes - c->in_have;
        ssize_t k = recv(c->fd, p, n, MSG_DONTWAIT);
        if (k == 0) return fail(c, "the connection was closed", 0);
        if (k < 0) {
            if (errno == EINTR) continue;
            if (errno == EAGAIN || errno == EWOULDBLOCK) return 0;
            return fail(c, NULL, errno);
        }
        c->bytes_in += (uint64_t)k;
        if (!in_header) {
            c->in_have += (size_t)k;
            continue;
        }
        c->hdr_have += (size_t)k;
        if (c->hdr_have < sizeof c->hdr) continue;
        if (c->hdr.check != (MPIR_MAGIC ^ c->hdr.type)) return fail(c, "it sent bytes that are not a raypack frame", 0);
        if (c->hdr.bytes > c->max_in) {
            snprintf(c->err, sizeof c->err, "it sent a %llu-byte frame (at most %llu)",
                     (unsigned long long)c->hdr.bytes, (unsigned long long)c->max_in);
            return -1;
        }
        if (c->hdr.bytes > c->in_cap) {
            uint8_t *q = realloc(c->in, (size_t)c->hdr.bytes);
            if (!q) return fail(c, "out of memory for a frame", 0);
            c->in = q;
            c->in_cap = (size_t)c->hdr.bytes;
        }
    }
}

void mpir_conn_next(mpir_conn *c) { c->hdr_have = c->in_have = 0; }

int mpir_conn_send_idle(mpir_conn *c, double idle_s) {
    double last = mpir_now_s();
    for (;;) {
        uint64_t before = c->bytes_out;
        int rc = mpir_conn_flush(c);
        if (rc != 0) return rc;
        double now = mpir_now_s();
        if (c->bytes_out != before) last = now;
        if (now - last > idle_s) return 0;
        struct pollfd p = {.fd = c->fd, .events = POLLOUT};
        poll(&p, 1, 100);
    }
}

int mpir_conn_recv_idle(mpir_conn *c, double idle_s) {
    double last = mpir_now_s();
    for (;;) {
        uint64_t before = c->bytes_in;
        int rc = mpir_conn_read(c);
        if (rc != 0) return rc;
        double now = mpir_now_s();
        if (c->bytes_in != before) last = now;
        if (now - last > idle_s) return 0;
        struct pollfd p = {.fd = c->fd, .events = POLLIN};
        poll(&p, 1, 100);
    }
}
