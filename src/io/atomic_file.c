/* Outputs written whole or not at all: every file raypack writes goes to a temporary file in the
 * destination's folder (so the rename stays on one file system) and replaces the destination only
 * once every byte has been written and flushed; a full disk or a file-size limit leaves the old file
 * as it was and removes the temporary one. */
#define _GNU_SOURCE
#include "raypack_io.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

struct rp_atomic_file {
    FILE *f;
    char *path; /* destination (a symbolic link's target, so the link survives) */
    char *tmp;  /* temporary file beside it */
    bool failed;
    int err;    /* errno of the first failed write seen by rp_atomic_fail */
};

static void set_err(char *err, size_t err_size, const char *path, const char *fmt, ...) {
    if (!err || err_size == 0) return;
    int n = snprintf(err, err_size, "%s: error: ", path);
    if (n < 0 || (size_t)n >= err_size) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err + n, err_size - (size_t)n, fmt, ap);
    va_end(ap);
}

/* The file a write to `path` should replace: the target of a symbolic link, else path itself. */
static char *destination(const char *path) {
    struct stat st;
    if (lstat(path, &st) == 0 && S_ISLNK(st.st_mode)) {
        char *real = realpath(path, NULL);
        if (real) return real;
    }
    return strdup(path);
}

rp_atomic_file *rp_atomic_open(const char *path, char *err, size_t err_size) {
    if (!path || !path[0]) {
        set_err(err, err_size, path ? path : "(null)", "no output path");
        return NULL;
    }
    rp_atomic_file *af = calloc(1, sizeof *af);
    if (af) af->path = destination(path);
    size_t n = af && af->path ? strlen(af->path) : 0;
    if (af && af->path) af->tmp = malloc(n + 64);
    if (!af || !af->path || !af->tmp) {
        set_err(err, err_size, path, "out of memory");
        if (af) free(af->path), free(af->tmp);
        free(af);
        return NULL;
    }
    struct stat st;
    if (stat(af->path, &st) == 0 && !S_ISREG(st.st_mode)) {
        /* A device, FIFO or folder is not replaced by a regular file. */
        set_err(err, err_size, path, S_ISDIR(st.st_mode) ? "it is a directory" : "not a regular file");
        free(af->path), free(af->tmp), free(af);
        return NULL;
    }
    /* ".NAME.PID.N.tmp" in the same folder; O_EXCL so two writers never share one, 0666 so the
     * umask decides the mode as it would for a file opened in place. */
    const char *slash = strrchr(af->path, '/');
    int dir_len = slash ? (int)(slash - af->path) + 1 : 0;
    static atomic_uint counter;
    int fd = -1, e = 0;
    for (int attempt = 0; attempt < 100 && fd < 0; attempt++) {
        unsigned k = atomic_fetch_add(&counter, 1u) ^ (unsigned)time(NULL) * 2654435761u;
        snprintf(af->tmp, n + 64, "%.*s.%s.%ld.%x.tmp", dir_len, af->path, af->path + dir_len, (long)getpid(), k);
        fd = open(af->tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
        e = errno;
        if (fd < 0 && e != EEXIST) break;
    }
    if (fd < 0) {
        set_err(err, err_size, path, "cannot open for writing: %s", strerror(e));
        free(af->path), free(af->tmp), free(af);
        return NULL;
    }
    if (stat(af->path, &st) == 0) (void)fchmod(fd, st.st_mode & 07777); /* keep the old file's mode */
    af->f = fdopen(fd, "wb");
    if (!af->f) {
        e = errno;
        close(fd);
        unlink(af->tmp);
        set_err(err, err_size, path, "cannot open for writing: %s", strerror(e));
        free(af->path), free(af->tmp), free(af);
        return NULL;
    }
    return af;
}

void *rp_atomic_stream(rp_atomic_file *af) { return af ? af->f : NULL; }

const char *rp_atomic_temp_path(const rp_atomic_file *af) { return af ? af->tmp : NULL; }

void rp_atomic_fail(rp_atomic_file *af, int errnum) {
    if (!af || af->failed) return;
    af->failed = true;
    af->err = errnum;
}

static void destroy(rp_atomic_file *af) {
    free(af->path);
    free(af->tmp);
    free(af);
}

void rp_atomic_abort(rp_atomic_file *af) {
    if (!af) return;
    if (af->f) fclose(af->f);
    unlink(af->tmp);
    destroy(af);
}

bool rp_atomic_commit(rp_atomic_file *af, char *err, size_t err_size) {
    if (!af) return false;
    /* A write past RLIMIT_FSIZE raises SIGXFSZ, whose default action kills the process before this
     * clean-up: programs set it to ignored (the raypack command does) and get EFBIG here instead. */
    int e = af->failed ? (af->err ? af->err : EIO) : 0;
    if (!e && ferror(af->f)) e = errno ? errno : EIO;
    if (!e && fflush(af->f) != 0) e = errno;
    if (!e && fsync(fileno(af->f)) != 0 && errno != EINVAL && errno != EROFS) e = errno;
    if (fclose(af->f) != 0 && !e) e = errno;
    af->f = NULL;
    if (!e && rename(af->tmp, af->path) != 0) e = errno;
    if (e) {
        unlink(af->tmp);
        set_err(err, err_size, af->path, "write failed: %s", strerror(e));
        destroy(af);
        return false;
    }
    destroy(af);
    return true;
}

bool rp_atomic_write(const char *path, bool (*write)(void *stream, void *user), void *user, char *err,
                     size_t err_size) {
    rp_atomic_file *af = rp_atomic_open(path, err, err_size);
    if (!af) return false;
    errno = 0;
    if (!write(af->f, user)) rp_atomic_fail(af, errno ? errno : EIO);
    return rp_atomic_commit(af, err, err_size);
}
