/* Files for the loaders: whole files read into memory, gzip'd or not (zlib reads plain files
 * through the same calls), and tar archives (libarchive) whose entries then serve the includes and
 * textures of the scene inside them. */
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "io/io_internal.h"

/* Records why a read failed (ctx->why, for the caller's message); returns false. */
__attribute__((format(printf, 2, 3))) static bool vfs_fail(io_ctx *ctx, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(ctx->why, sizeof ctx->why, fmt, ap);
    va_end(ap);
    return false;
}

#if RP_IO_HAVE_LIBDEFLATE
#include <libdeflate.h>
#endif
#if RP_IO_HAVE_ARCHIVE
#include <archive.h>
#include <archive_entry.h>
#endif

void vfs_buf_free(io_buf *buf) {
    if (buf->owned) free(buf->data);
    memset(buf, 0, sizeof *buf);
}

/* zlib's message without the "<fd:3>: " that gzdopen's streams put in front. */
static const char *zlib_reason(const char *msg) {
    if (!msg || !msg[0]) return "zlib error";
    const char *colon = msg[0] == '<' ? strstr(msg, ">: ") : NULL;
    return colon ? colon + 3 : msg;
}

#if RP_IO_HAVE_LIBDEFLATE
/* deflate expands at most 1032:1; a gzip trailer claiming more than that is a lie */
#define DEFLATE_MAX_RATIO 1032u

/* Page faults on the output cost about as much as inflating into it (182 MB of the SPD tree: some
 * 45,000 faults). With a second thread those pages are mapped ahead of libdeflate while it writes
 * (MADV_POPULATE_WRITE maps a page without touching its contents, so it is harmless on pages the
 * inflater has already written); inflating then runs at the speed of a warm buffer. */
#define PREFAULT_MIN_BYTES (8u << 20)
#define PREFAULT_STEP (2u << 20)

typedef struct prefault_job {
    char *lo, *hi; /* page-aligned span inside the buffer */
} prefault_job;

static void *prefault_run(void *arg) {
#ifdef MADV_POPULATE_WRITE
    prefault_job *job = arg;
    for (char *p = job->lo; p < job->hi; p += PREFAULT_STEP) {
        size_t n = (size_t)(job->hi - p) < PREFAULT_STEP ? (size_t)(job->hi - p) : PREFAULT_STEP;
        if (madvise(p, n, MADV_POPULATE_WRITE) != 0) break; /* an older kernel: the inflater faults them */
    }
#else
    (void)arg;
#endif
    return NULL;
}

/* Starts the prefaulting thread for data[0, size); false when none was started. */
static bool prefault_start(char *data, size_t size, prefault_job *job, pthread_t *tid) {
    long page = sysconf(_SC_PAGESIZE);
    if (size < PREFAULT_MIN_BYTES || page <= 0) return false;
    uintptr_t mask = (uintptr_t)page - 1;
    job->lo = (char *)(((uintptr_t)data + mask) & ~mask);
    job->hi = (char *)(((uintptr_t)data + size) & ~mask);
    return job->hi > job->lo && pthread_create(tid, NULL, prefault_run, job) == 0;
}

/* The fast path for a regular gzip file (1.5-3.7x faster than zlib's stream on the shared scenes):
 * the compressed file read whole (fd, at its start) and inflated by libdeflate in one call into
 * the size its trailer states, once that size is checked against what the file can hold (the
 * ratio above) and against the limit. False, with nothing allocated and fd back at its start,
 * whenever that does not work out (not gzip, a lying trailer, several members, corrupt data): the
 * caller then streams the file with zlib, which says what went wrong. */
static bool deflate_read(int fd, size_t file_size, uint64_t limit, bool prefault, io_buf *out) {
    unsigned char magic[2];
    if (file_size < 18 || file_size > limit || pread(fd, magic, 2, 0) != 2 || magic[0] != 0x1f || magic[1] != 0x8b)
        return false; /* not gzip: not read twice */
    unsigned char *in = io_malloc(file_size);
    if (!in) return false;
    size_t got = 0;
    while (got < file_size) {
        ssize_t r = read(fd, in + got, file_size - got);
        if (r <= 0) break;
        got += (size_t)r;
    }
    bool ok = got == file_size && in[0] == 0x1f && in[1] == 0x8b;
    size_t hint = 0;
    if (ok) {
        const unsigned char *t = in + file_size - 4;
        hint = (size_t)t[0] | (size_t)t[1] << 8 | (size_t)t[2] << 16 | (size_t)t[3] << 24;
        ok = hint > 0 && hint <= limit && hint / DEFLATE_MAX_RATIO <= file_size;
    }
    char *data = ok ? io_malloc(hint + 1) : NULL;
    struct libdeflate_decompressor *d = data && io_alloc_ok(1) ? libdeflate_alloc_decompressor() : NULL;
    prefault_job job;
    pthread_t tid;
    bool prefaulting = d && prefault && prefault_start(data, hint, &job, &tid);
    size_t used = 0, size = 0;
    ok = d && libdeflate_gzip_decompress_ex(d, in, file_size, data, hint, &used, &size) == LIBDEFLATE_SUCCESS &&
         used == file_size;
    if (prefaulting) pthread_join(tid, NULL);
    if (d) libdeflate_free_decompressor(d);
    free(in);
    if (!ok) {
        free(data);
        (void)lseek(fd, 0, SEEK_SET);
        return false;
    }
    data[size] = '\0';
    out->data = data;
    out->size = size;
    out->owned = true;
    return true;
}
#endif

/* Reads a file whole, inflating gzip as a stream: the size trailer of a gzip file is never trusted
 * (an 18-byte file may claim 4 GiB), the buffer grows geometrically from the file's size and the
 * inflated size is capped (ctx->limits.max_file_bytes). FIFOs and other streams are read the same
 * way, opened once. */
static bool disk_read(io_ctx *ctx, const char *path, io_buf *out) {
    /* a device never ends (/dev/zero: 4 GiB read before the size limit) or may block on open (a
     * terminal): refused before opening it, by stat, which leaves a FIFO's bytes to the read below */
    struct stat st;
    if (stat(path, &st) == 0 && (S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) || S_ISSOCK(st.st_mode)))
        return vfs_fail(ctx, "a device or socket, not a file");
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return vfs_fail(ctx, "%s", strerror(errno));
    if (fstat(fd, &st) != 0) {
        int e = errno;
        close(fd);
        return vfs_fail(ctx, "%s", strerror(e));
    }
    if (S_ISDIR(st.st_mode)) {
        close(fd);
        return vfs_fail(ctx, "%s", strerror(EISDIR));
    }
    uint64_t limit = ctx->limits.max_file_bytes;
#if RP_IO_HAVE_LIBDEFLATE
    if (S_ISREG(st.st_mode) && deflate_read(fd, (size_t)st.st_size, limit, ctx->threads > 1, out)) {
        close(fd);
        return true;
    }
#endif
    size_t cap = S_ISREG(st.st_mode) && st.st_size > 0 ? (size_t)st.st_size + 1 : 65536;
    if (cap > limit + 1) cap = (size_t)limit + 1;
    gzFile gz = io_alloc_ok(1u << 18) ? gzdopen(fd, "rb") : NULL;
    if (!gz) {
        close(fd);
        return vfs_fail(ctx, "out of memory");
    }
    gzbuffer(gz, 1u << 18);
    char *data = io_malloc(cap + 1);
    size_t size = 0;
    bool ok = data != NULL, too_big = false;
    if (!ok) vfs_fail(ctx, "out of memory");
    while (ok) {
        if (size == cap) {
            if (size > limit) {
                too_big = true;
                break;
            }
            size_t grown = cap <= SIZE_MAX / 4 ? cap * 2 : SIZE_MAX / 2;
            if (grown > limit + 1) grown = (size_t)limit + 1;
            char *d = io_realloc(data, grown + 1);
            if (!d) {
                ok = vfs_fail(ctx, "out of memory after %zu bytes", size);
                break;
            }
            data = d;
            cap = grown;
        }
        size_t want = cap - size;
        if (want > (1u << 30)) want = 1u << 30;
        int got = gzread(gz, data + size, (unsigned)want);
        if (got < 0) {
            int errnum = Z_OK;
            const char *msg = gzerror(gz, &errnum);
            ok = errnum == Z_ERRNO ? vfs_fail(ctx, "%s", strerror(errno))
                                   : vfs_fail(ctx, "corrupt or truncated gzip data (%s)", zlib_reason(msg));
        }
        if (got <= 0) break;
        size += (size_t)got;
    }
    if (ok && too_big)
        ok = vfs_fail(ctx, "more than %llu bytes (decompressed); RP_MAX_FILE_BYTES raises the limit",
                      (unsigned long long)limit);
    if (ok) {
        int errnum = Z_OK;
        const char *msg = gzerror(gz, &errnum);
        if (errnum != Z_OK && errnum != Z_STREAM_END) /* truncated or corrupt gzip */
            ok = vfs_fail(ctx, "corrupt or truncated gzip data (%s)", zlib_reason(msg));
    }
    gzclose(gz);
    if (!ok) {
        free(data);
        return false;
    }
    data[size] = '\0';
    out->data = data;
    out->size = size;
    out->owned = true;
    return true;
}

static const io_entry *vfs_find(const io_vfs *vfs, const char *path) {
    for (size_t i = 0; i < vfs->entry_count; i++)
        if (strcmp(vfs->entries[i].name, path) == 0) return &vfs->entries[i];
    return NULL;
}

bool vfs_read(io_ctx *ctx, const char *path, io_buf *out) {
    memset(out, 0, sizeof *out);
    ctx->why[0] = '\0';
    if (!ctx->vfs.archive) return disk_read(ctx, path, out);
    const io_entry *e = vfs_find(&ctx->vfs, path);
    if (!e) return vfs_fail(ctx, "no such file in the archive");
    out->data = e->data;
    out->size = e->size;
    out->owned = false;
    return true;
}

bool vfs_exists(io_ctx *ctx, const char *path) {
    if (ctx->vfs.archive) return vfs_find(&ctx->vfs, path) != NULL;
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

/* Lexical normalization of a relative archive path: drops "." and empty parts, resolves "..". */
static void normalize(char *s) {
    char *parts[256];
    int n = 0;
    char *save = NULL;
    char tmp[IO_PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s", s);
    for (char *tok = strtok_r(tmp, "/", &save); tok; tok = strtok_r(NULL, "/", &save)) {
        if (strcmp(tok, ".") == 0) continue;
        if (strcmp(tok, "..") == 0) {
            if (n > 0) n--;
            continue;
        }
        if (n < 256) parts[n++] = tok;
    }
    size_t len = 0;
    s[0] = '\0';
    for (int i = 0; i < n; i++) {
        size_t k = strlen(parts[i]);
        if (len + k + 2 > IO_PATH_MAX) break;
        if (i) s[len++] = '/';
        memcpy(s + len, parts[i], k + 1);
        len += k;
    }
}

void vfs_join(const io_vfs *vfs, const char *base, const char *rel, char *out, size_t size) {
    const char *slash = strrchr(base, '/');
    int dir_len = slash ? (int)(slash - base) : 0;
    if (rel[0] == '/')
        snprintf(out, size, "%s", vfs->archive ? rel + 1 : rel);
    else if (slash)
        snprintf(out, size, "%.*s/%s", dir_len, base, rel);
    else
        snprintf(out, size, "%s", rel);
    if (vfs->archive && size >= IO_PATH_MAX) normalize(out);
}

void vfs_display(const io_vfs *vfs, const char *path, char *out, size_t size) {
    if (vfs->archive)
        snprintf(out, size, "%s/%s", vfs->archive, path);
    else
        snprintf(out, size, "%s", path);
}

const char *vfs_find_basename(const io_vfs *vfs, const char *name) {
    const char *found = NULL;
    for (size_t i = 0; i < vfs->entry_count; i++) {
        const char *n = vfs->entries[i].name;
        const char *slash = strrchr(n, '/');
        if (strcmp(slash ? slash + 1 : n, name) != 0) continue;
        if (found) return NULL; /* ambiguous */
        found = n;
    }
    return found;
}

void vfs_extension(const char *path, char *ext, size_t size) {
    const char *slash = strrchr(path, '/');
    const char *name = slash ? slash + 1 : path;
    char tmp[256];
    snprintf(tmp, sizeof tmp, "%s", name);
    for (char *c = tmp; *c; c++)
        if (*c >= 'A' && *c <= 'Z') *c = (char)(*c + 32);
    size_t n = strlen(tmp);
    if (n > 3 && strcmp(tmp + n - 3, ".gz") == 0) tmp[n - 3] = '\0';
    const char *dot = strrchr(tmp, '.');
    snprintf(ext, size, "%s", dot ? dot + 1 : "");
}

/* True when p points into the inflated archive image (an entry left where it lies). */
static bool in_image(const io_buf *image, const char *p) {
    return image->data && p >= image->data && p <= image->data + image->size;
}

#if RP_IO_HAVE_ARCHIVE
/* Reads the current entry's data blocks: one block at offset 0 inside the image (a plain tar in
 * memory: every entry) is borrowed as is; anything else (sparse files) is assembled in a copy,
 * holes zero-filled. The bytes count against the limit like copied ones. */
static bool entry_from_blocks(io_ctx *ctx, struct archive *a, const char *path, const char *name, const io_buf *image,
                              const char **out, size_t *out_size, uint64_t *total) {
    uint64_t limit = ctx->limits.max_file_bytes;
    char *copy = NULL;
    const char *borrowed = NULL;
    size_t size = 0, cap = 0;
    for (;;) {
        const void *blk = NULL;
        size_t n = 0;
        la_int64_t off = 0;
        int r = archive_read_data_block(a, &blk, &n, &off);
        if (r == ARCHIVE_EOF) break;
        if (r != ARCHIVE_OK || off < 0) {
            free(copy);
            return io_error(ctx, path, 0, "corrupt archive entry '%s': %s", name, archive_error_string(a));
        }
        *total += n;
        if (*total > limit) {
            free(copy);
            return io_error(ctx, path, 0, "more than %llu bytes unpacked; RP_MAX_FILE_BYTES raises the limit",
                            (unsigned long long)limit);
        }
        if (!borrowed && !copy && off == 0 && in_image(image, blk) && in_image(image, (const char *)blk + n)) {
            borrowed = blk;
            size = n;
            continue;
        }
        size_t end = (size_t)off + n;
        if ((uint64_t)off > limit || end > limit) {
            free(copy);
            return io_error(ctx, path, 0, "more than %llu bytes unpacked; RP_MAX_FILE_BYTES raises the limit",
                            (unsigned long long)limit);
        }
        if (end + 1 > cap) {
            size_t c = cap ? cap : 4096;
            while (c < end + 1) c *= 2;
            char *g = realloc(copy, c);
            if (!g) {
                free(copy);
                return false;
            }
            if (!copy && borrowed) memcpy(g, borrowed, size); /* a second block: copy the first too */
            memset(g + (copy || borrowed ? size : 0), 0, c - (copy || borrowed ? size : 0));
            copy = g;
            cap = c;
            borrowed = NULL;
        }
        memcpy(copy + off, blk, n);
        if (end > size) size = end;
    }
    if (!copy && !borrowed) { /* empty */
        if (!(copy = calloc(1, 1))) return false;
    }
    if (copy) copy[size] = '\0';
    *out = copy ? copy : borrowed;
    *out_size = size;
    return true;
}
#endif

#if !RP_IO_HAVE_ARCHIVE
bool vfs_open_archive(io_ctx *ctx, const char *path, const void *data, size_t size) {
    (void)data, (void)size;
    return io_error(ctx, path, 0, "this build has no tar support (libarchive was not found)");
}
#else
bool vfs_open_archive(io_ctx *ctx, const char *path, const void *image, size_t image_size) {
    struct archive *a = io_alloc_ok(1) ? archive_read_new() : NULL;
    if (!a) return io_error(ctx, path, 0, "out of memory");
    archive_read_support_filter_all(a);
    archive_read_support_format_tar(a);
    archive_read_support_format_gnutar(a);
    io_buf raw = {0};
#if RP_IO_HAVE_LIBDEFLATE
    /* a .tar.gz inflated whole by libdeflate (deflate_read), then read as a plain tar */
    struct stat st;
    if (!image && stat(path, &st) == 0 && S_ISREG(st.st_mode)) { /* not a FIFO: read once, below */
        int fd = open(path, O_RDONLY | O_CLOEXEC);
        if (fd >= 0 && fstat(fd, &st) == 0 && S_ISREG(st.st_mode) &&
            deflate_read(fd, (size_t)st.st_size, ctx->limits.max_file_bytes, ctx->threads > 1, &raw))
            image = raw.data, image_size = raw.size;
        if (fd >= 0) close(fd);
    }
#endif
    int orc = image ? archive_read_open_memory(a, image, image_size) : archive_read_open_filename(a, path, 1u << 16);
    if (orc != ARCHIVE_OK) {
        bool r = io_error(ctx, path, 0, "cannot open archive: %s", archive_error_string(a));
        archive_read_free(a);
        vfs_buf_free(&raw);
        return r;
    }
    ctx->vfs.archive = path;
    size_t cap = 0;
    uint64_t total = 0, limit = ctx->limits.max_file_bytes;
    struct archive_entry *entry;
    bool ok = true;
    int rc;
    while ((rc = archive_read_next_header(a, &entry)) == ARCHIVE_OK) {
        if (archive_entry_filetype(entry) != AE_IFREG) continue;
        const char *name = archive_entry_pathname(entry);
        if (!name) continue;
        char norm[IO_PATH_MAX];
        snprintf(norm, sizeof norm, "%s", name[0] == '/' ? name + 1 : name);
        normalize(norm);
        if (raw.data) { /* the image is ours: entries that lie in it in one piece stay there */
            const char *data = NULL;
            size_t size = 0;
            if (!io_reserve((void **)&ctx->vfs.entries, &cap, ctx->vfs.entry_count + 1, sizeof(io_entry)) ||
                !entry_from_blocks(ctx, a, path, norm, &raw, &data, &size, &total)) {
                ok = ctx->failed ? false : io_error(ctx, path, 0, "out of memory");
                break;
            }
            char *dup = strdup(norm);
            if (!dup) {
                if (!in_image(&raw, data)) free((char *)data);
                ok = io_error(ctx, path, 0, "out of memory");
                break;
            }
            io_entry *e = &ctx->vfs.entries[ctx->vfs.entry_count++];
            e->name = dup;
            e->data = (char *)data;
            e->size = size;
            continue;
        }
        /* The header's size is a hint, never an allocation: a 512-byte header may claim 8 GiB. */
        la_int64_t declared = archive_entry_size(entry);
        size_t ecap = declared > 0 && declared < (1 << 20) ? (size_t)declared : declared > 0 ? (size_t)1 << 20 : 4096;
        size_t size = 0;
        char *data = io_malloc(ecap + 1);
        if (!data || !io_reserve((void **)&ctx->vfs.entries, &cap, ctx->vfs.entry_count + 1, sizeof(io_entry))) {
            free(data);
            ok = io_error(ctx, path, 0, "out of memory");
            break;
        }
        for (;;) {
            if (size == ecap) {
                char *d = ecap <= SIZE_MAX / 4 ? io_realloc(data, 2 * ecap + 1) : NULL;
                if (!d) {
                    ok = io_error(ctx, path, 0, "out of memory");
                    break;
                }
                data = d;
                ecap *= 2;
            }
            la_ssize_t got = archive_read_data(a, data + size, ecap - size);
            if (got < 0) {
                ok = io_error(ctx, path, 0, "corrupt archive entry '%s': %s", norm, archive_error_string(a));
                break;
            }
            if (got == 0) break;
            size += (size_t)got;
            total += (uint64_t)got;
            if (total > limit) {
                ok = io_error(ctx, path, 0, "more than %llu bytes unpacked; RP_MAX_FILE_BYTES raises the limit",
                              (unsigned long long)limit);
                break;
            }
        }
        char *dup = ok ? io_strdup(norm) : NULL;
        if (!ok || !dup) {
            free(data);
            free(dup);
            if (ok) ok = io_error(ctx, path, 0, "out of memory");
            break;
        }
        data[size] = '\0';
        io_entry *e = &ctx->vfs.entries[ctx->vfs.entry_count++];
        e->name = dup;
        e->data = data;
        e->size = size;
    }
    if (ok && rc != ARCHIVE_EOF)
        ok = io_error(ctx, path, 0, "corrupt archive: %s", archive_error_string(a));
    archive_read_free(a);
    if (raw.data) {
        /* Entries in the image end with a NUL now that no header is read any more: the byte after an
         * entry is its padding or the next header (or the image's own NUL). */
        for (size_t i = 0; i < ctx->vfs.entry_count; i++)
            if (in_image(&raw, ctx->vfs.entries[i].data)) ctx->vfs.entries[i].data[ctx->vfs.entries[i].size] = '\0';
        ctx->vfs.image = raw.data, ctx->vfs.image_size = raw.size;
        memset(&raw, 0, sizeof raw);
    }
    return ok;
}
#endif

void vfs_close(io_vfs *vfs) {
    io_buf image = {.data = vfs->image, .size = vfs->image_size, .owned = true};
    for (size_t i = 0; i < vfs->entry_count; i++) {
        free(vfs->entries[i].name);
        if (!in_image(&image, vfs->entries[i].data)) free(vfs->entries[i].data);
    }
    free(vfs->entries);
    free(vfs->image);
    memset(vfs, 0, sizeof *vfs);
}
