/* A gzip'd text file read in blocks: a thread inflates it with zlib's stream (every member of a
 * multi-member file, as gzread reads them) into a few reused buffers while the loader parses the
 * block before, so the inflated text is never held whole. 182 MB of SPD tree text held whole cost
 * more in page faults on this kind of virtual machine than inflating and parsing it (docs/loading.md);
 * four blocks of 8 MiB are faulted in once and reused.
 *
 * A block ends at a line start the caller's cut function picks (a token never straddles two
 * blocks), the partial line after it carried into the next block; a line longer than a block makes
 * the block grow until it ends. Errors (corrupt or truncated data, the size limit) are zlib's
 * messages in the words disk_read uses, so a streamed load fails as a whole-buffer one does. */
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "io/io_internal.h"

#define STREAM_SLOTS 4

typedef struct stream_slot {
    char *data; /* NUL at data[size] */
    size_t size, cap;
    bool last;
} stream_slot;

struct io_stream {
    gzFile gz;
    size_t block;
    io_cut_fn cut;
    uint64_t limit, total;
    uint64_t hint; /* the inflated size the gzip trailer states, when plausible; 0 otherwise */
    pthread_t tid;
    bool started;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    stream_slot slot[STREAM_SLOTS];
    uint64_t made, taken, freed; /* blocks published, handed out, given back (in order) */
    bool done, failed, quit;
    char why[256];
    char *carry; /* the partial line after the last cut */
    size_t carry_n, carry_cap;
};

__attribute__((format(printf, 2, 3))) static void stream_fail(io_stream *s, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    pthread_mutex_lock(&s->mu);
    vsnprintf(s->why, sizeof s->why, fmt, ap);
    s->failed = s->done = true;
    pthread_cond_broadcast(&s->cv);
    pthread_mutex_unlock(&s->mu);
    va_end(ap);
}

/* zlib's message without the "<fd:3>: " that gzdopen's streams put in front (as disk_read). */
static const char *stream_reason(const char *msg) {
    if (!msg || !msg[0]) return "zlib error";
    const char *colon = msg[0] == '<' ? strstr(msg, ">: ") : NULL;
    return colon ? colon + 3 : msg;
}

/* Makes room for cap bytes and the NUL in a slot, keeping its first `keep` bytes; false when out of
 * memory. An empty slot is allocated anew rather than copied (realloc would copy stale text). */
static bool slot_room(stream_slot *b, size_t cap, size_t keep) {
    if (cap <= b->cap) return true;
    size_t c = b->cap ? b->cap : cap + cap / 8; /* room for a carried line without growing */
    while (c < cap) c = c <= SIZE_MAX / 4 ? 2 * c : cap;
    char *d;
    if (keep) {
        d = io_realloc(b->data, c + 1);
    } else {
        free(b->data);
        b->data = NULL;
        b->cap = 0;
        d = io_malloc(c + 1);
    }
    if (!d) return false;
    b->data = d;
    b->cap = c;
    return true;
}

/* Inflates into b until it holds `want` bytes or the file ends; false after an error. */
static bool stream_fill(io_stream *s, stream_slot *b, size_t want, bool *eof) {
    while (b->size < want) {
        size_t n = want - b->size;
        if (n > (1u << 30)) n = 1u << 30;
        int got = gzread(s->gz, b->data + b->size, (unsigned)n);
        if (got < 0) {
            int errnum = Z_OK;
            const char *msg = gzerror(s->gz, &errnum);
            if (errnum == Z_ERRNO) stream_fail(s, "%s", strerror(errno));
            else stream_fail(s, "corrupt or truncated gzip data (%s)", stream_reason(msg));
            return false;
        }
        if (got == 0) {
            int errnum = Z_OK;
            const char *msg = gzerror(s->gz, &errnum);
            if (errnum != Z_OK && errnum != Z_STREAM_END) { /* truncated or corrupt */
                stream_fail(s, "corrupt or truncated gzip data (%s)", stream_reason(msg));
                return false;
            }
            *eof = true;
            return true;
        }
        b->size += (size_t)got;
        s->total += (uint64_t)got;
        if (s->total > s->limit) {
            stream_fail(s, "more than %llu bytes (decompressed); RP_MAX_FILE_BYTES raises the limit",
                        (unsigned long long)s->limit);
            return false;
        }
    }
    return true;
}

static void *stream_run(void *arg) {
    io_stream *s = arg;
    for (;;) {
        pthread_mutex_lock(&s->mu);
        while (!s->quit && s->made - s->freed >= STREAM_SLOTS) pthread_cond_wait(&s->cv, &s->mu);
        bool quit = s->quit;
        stream_slot *b = &s->slot[s->made % STREAM_SLOTS];
        pthread_mutex_unlock(&s->mu);
        if (quit) return NULL;
        /* the first block smaller, so that parsing starts sooner (the rest inflate meanwhile) */
        size_t want = s->carry_n + (s->made == 0 && s->block > IO_STREAM_MIN_BLOCK ? s->block / 4 : s->block);
        if (!slot_room(b, s->carry_n + s->block, 0)) { /* sized for every block the slot will hold */
            stream_fail(s, "out of memory");
            return NULL;
        }
        if (s->carry_n) memcpy(b->data, s->carry, s->carry_n);
        b->size = s->carry_n;
        s->carry_n = 0;
        bool eof = false;
        size_t cut = 0;
        for (;;) {
            if (!stream_fill(s, b, want, &eof)) return NULL;
            if (eof) {
                cut = b->size;
                break;
            }
            cut = s->cut(b->data, b->size);
            if (cut) break;
            /* no line start: a line longer than the block, which grows until it ends */
            want = b->size + s->block;
            if (!slot_room(b, want, b->size)) {
                stream_fail(s, "out of memory");
                return NULL;
            }
        }
        size_t rest = b->size - cut;
        if (rest) {
            if (!io_reserve((void **)&s->carry, &s->carry_cap, rest, 1)) {
                stream_fail(s, "out of memory");
                return NULL;
            }
            memcpy(s->carry, b->data + cut, rest);
            s->carry_n = rest;
        }
        b->size = cut;
        b->data[cut] = '\0';
        b->last = eof;
        pthread_mutex_lock(&s->mu);
        s->made++;
        if (eof) s->done = true;
        pthread_cond_broadcast(&s->cv);
        pthread_mutex_unlock(&s->mu);
        if (eof) return NULL;
    }
}

size_t io_cut_lines(const char *data, size_t size) {
    for (size_t i = size; i > 0; i--)
        if (data[i - 1] == '\n') return i;
    return 0;
}

io_stream *io_stream_open(io_ctx *ctx, const char *path, size_t min_text, size_t block, io_cut_fn cut) {
    struct stat st;
    /* stat first: opening a FIFO here would take its writer's bytes and drop them on close, and the
     * reader that follows (vfs_read) would then wait for a writer forever */
    if (stat(path, &st) != 0 || !S_ISREG(st.st_mode)) return NULL;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return NULL;
    unsigned char magic[2];
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode) || pread(fd, magic, 2, 0) != 2 || magic[0] != 0x1f ||
        magic[1] != 0x8b) {
        close(fd);
        return NULL;
    }
    /* deflate expands at most 1032:1: a trailer claiming more lies (and a multi-member file's
     * trailer only gives its last member's size, so this is a hint, for choosing and presizing) */
    uint64_t hint = 0;
    unsigned char t[4];
    if (st.st_size >= 18 && pread(fd, t, 4, st.st_size - 4) == 4) {
        uint64_t n = (uint64_t)t[0] | (uint64_t)t[1] << 8 | (uint64_t)t[2] << 16 | (uint64_t)t[3] << 24;
        if (n / 1032 <= (uint64_t)st.st_size && n <= ctx->limits.max_file_bytes) hint = n;
    }
    if (hint < min_text) {
        close(fd);
        return NULL;
    }
    io_stream *s = io_calloc(1, sizeof *s);
    gzFile gz = s && io_alloc_ok(1u << 18) ? gzdopen(fd, "rb") : NULL;
    if (!gz) {
        free(s);
        close(fd);
        return NULL;
    }
    gzbuffer(gz, 1u << 18);
    s->gz = gz;
    s->hint = hint;
    /* about eight blocks a file, so a smaller file's inflating overlaps its parsing too */
    s->block = block ? block : s->hint / 8 < IO_STREAM_MIN_BLOCK ? IO_STREAM_MIN_BLOCK
                             : s->hint / 8 > IO_STREAM_BLOCK   ? IO_STREAM_BLOCK
                                                               : (size_t)(s->hint / 8);

    s->cut = cut ? cut : io_cut_lines;
    s->limit = ctx->limits.max_file_bytes;
    pthread_mutex_init(&s->mu, NULL);
    pthread_cond_init(&s->cv, NULL);
    if (pthread_create(&s->tid, NULL, stream_run, s) != 0) {
        io_stream_close(s);
        return NULL;
    }
    s->started = true;
    return s;
}

bool io_stream_next(io_stream *s, io_ctx *ctx, io_text *out) {
    pthread_mutex_lock(&s->mu);
    while (s->taken == s->made && !s->done) pthread_cond_wait(&s->cv, &s->mu);
    bool ok = s->taken < s->made;
    if (ok) {
        const stream_slot *b = &s->slot[s->taken % STREAM_SLOTS];
        out->data = b->data;
        out->size = b->size;
        out->last = b->last;
        s->taken++;
    } else {
        snprintf(ctx->why, sizeof ctx->why, "%s", s->failed ? s->why : "read past the end");
    }
    pthread_mutex_unlock(&s->mu);
    return ok;
}

void io_stream_release(io_stream *s) {
    pthread_mutex_lock(&s->mu);
    if (s->freed < s->taken) s->freed++;
    pthread_cond_broadcast(&s->cv);
    pthread_mutex_unlock(&s->mu);
}

bool io_stream_drain(io_stream *s, io_ctx *ctx) {
    for (;;) {
        pthread_mutex_lock(&s->mu);
        bool finished = s->done && s->taken == s->made;
        bool failed = s->failed;
        pthread_mutex_unlock(&s->mu);
        if (finished) {
            if (failed) snprintf(ctx->why, sizeof ctx->why, "%s", s->why);
            return !failed;
        }
        io_text t;
        if (!io_stream_next(s, ctx, &t)) return false;
        io_stream_release(s);
    }
}

uint64_t io_stream_total(const io_stream *s) { return s->total; }

uint64_t io_stream_size_hint(const io_stream *s) { return s->hint; }

void io_stream_close(io_stream *s) {
    if (!s) return;
    if (s->started) {
        pthread_mutex_lock(&s->mu);
        s->quit = true;
        pthread_cond_broadcast(&s->cv);
        pthread_mutex_unlock(&s->mu);
        pthread_join(s->tid, NULL);
    }
    gzclose(s->gz);
    pthread_mutex_destroy(&s->mu);
    pthread_cond_destroy(&s->cv);
    for (int i = 0; i < STREAM_SLOTS; i++) free(s->slot[i].data);
    free(s->carry);
    free(s);
}
