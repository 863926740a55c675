/* Atomic outputs (rp_atomic_*, rp_image_write): a write that fails part-way (a file-size limit, a
 * writer that gives up) leaves the previous file byte for byte and no temporary file behind; one that
 * succeeds replaces the file whole, keeps its mode and a symbolic link pointing at it. */
#include <dirent.h>
#include <errno.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "raypack_io.h"
#include "rp_test.h"

static char dir[1024];

static bool write_text(const char *path, const char *text) {
    FILE *f = fopen(path, "wb");
    if (!f) return false;
    bool ok = fputs(text, f) >= 0;
    return fclose(f) == 0 && ok;
}

static bool file_is(const char *path, const char *text) {
    static char buf[1 << 16];
    FILE *f = fopen(path, "rb");
    if (!f) return false;
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = '\0';
    return n == strlen(text) && memcmp(buf, text, n) == 0;
}

/* Number of entries of dir whose name ends in ".tmp" (temporary files left behind). */
static int temp_files(void) {
    DIR *d = opendir(dir);
    if (!d) return -1;
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        size_t k = strlen(e->d_name);
        if (k > 4 && strcmp(e->d_name + k - 4, ".tmp") == 0) n++;
    }
    closedir(d);
    return n;
}

static bool give_up(void *stream, void *user) {
    (void)user;
    fputs("half of a file", stream);
    return false;
}

static bool write_hello(void *stream, void *user) {
    return fputs((const char *)user, stream) >= 0;
}

/* rp_image_write of a 256x256 image in a child limited to 4 KiB files: returns the child's view
 * (1 when rp_image_write failed naming the cause, 0 when it succeeded, -1 otherwise). */
static int write_limited(const char *path, const char *ext) {
    pid_t pid = fork();
    if (pid == 0) {
        signal(SIGXFSZ, SIG_IGN); /* EFBIG instead of death, as the raypack command sets it */
        struct rlimit rl = {4096, 4096};
        setrlimit(RLIMIT_FSIZE, &rl);
        static float px[256 * 256 * 3];
        for (size_t i = 0; i < sizeof px / sizeof px[0]; i++) px[i] = (float)((i * 2654435761u) % 1000) / 1000.0f;
        char err[512] = "";
        bool ok = rp_image_write(path, 256, 256, 3, px, err, sizeof err);
        if (!ok) fprintf(stderr, "(%s, expected) %s\n", ext, err);
        _exit(ok ? 0 : strstr(err, strerror(EFBIG)) ? 1 : 2);
    }
    int st = 0;
    if (pid < 0 || waitpid(pid, &st, 0) != pid || !WIFEXITED(st)) return -1;
    return WEXITSTATUS(st) == 0 ? 0 : WEXITSTATUS(st) == 1 ? 1 : -1;
}

int main(void) {
    const char *t = getenv("RP_TEST_TMP");
    snprintf(dir, sizeof dir, "%s", t ? t : "/tmp/raypack_test_output");
    mkdir(dir, 0777);
    char path[1200], err[512];

    /* A writer that fails: the old file stays, the temporary one goes. */
    snprintf(path, sizeof path, "%s/keep.json", dir);
    CHECK(write_text(path, "old content\n"));
    CHECK(!rp_atomic_write(path, give_up, NULL, err, sizeof err));
    CHECKF(file_is(path, "old content\n"), "a failed write changed %s", path);
    CHECK(temp_files() == 0);

    /* A writer that succeeds replaces it whole, keeping its mode. */
    chmod(path, 0640);
    CHECK(rp_atomic_write(path, write_hello, "new\n", err, sizeof err));
    CHECK(file_is(path, "new\n"));
    struct stat st;
    CHECK(stat(path, &st) == 0 && (st.st_mode & 0777) == 0640);
    CHECK(temp_files() == 0);

    /* Aborted by hand, and through the pair API. */
    rp_atomic_file *af = rp_atomic_open(path, err, sizeof err);
    CHECK(af && rp_atomic_temp_path(af) && access(rp_atomic_temp_path(af), F_OK) == 0);
    if (af) {
        fputs("discarded", (FILE *)rp_atomic_stream(af));
        rp_atomic_abort(af);
    }
    CHECK(file_is(path, "new\n") && temp_files() == 0);
    af = rp_atomic_open(path, err, sizeof err);
    if (af) {
        fputs("partial", (FILE *)rp_atomic_stream(af));
        rp_atomic_fail(af, ENOSPC);
    }
    CHECK(af && !rp_atomic_commit(af, err, sizeof err) && strstr(err, strerror(ENOSPC)));
    CHECK(file_is(path, "new\n") && temp_files() == 0);

    /* A symbolic link stays a link; its target gets the new content. */
    char link[1200];
    snprintf(link, sizeof link, "%s/link.json", dir);
    unlink(link);
    CHECK(symlink(path, link) == 0);
    CHECK(rp_atomic_write(link, write_hello, "via link\n", err, sizeof err));
    CHECK(lstat(link, &st) == 0 && S_ISLNK(st.st_mode) && file_is(path, "via link\n"));

    /* Not a file: a directory and a missing folder are refused with the reason. */
    CHECK(!rp_atomic_write(dir, write_hello, "x", err, sizeof err) && strstr(err, "directory"));
    snprintf(path, sizeof path, "%s/no/such/folder.json", dir);
    CHECK(!rp_atomic_write(path, write_hello, "x", err, sizeof err) && strstr(err, strerror(ENOENT)));

    /* Every image format under a file-size limit: the previous image survives intact. */
    static const char *const exts[] = {"png", "ppm", "pfm"};
    for (int i = 0; i < 3; i++) {
        snprintf(path, sizeof path, "%s/image.%s", dir, exts[i]);
        CHECK(write_text(path, "previous image\n"));
        int r = write_limited(path, exts[i]);
        CHECKF(r == 1, ".%s: rp_image_write under a 4 KiB limit gave %d (expected a failure naming EFBIG)",
               exts[i], r);
        CHECKF(file_is(path, "previous image\n"), ".%s: the failed write damaged the old image", exts[i]);
        CHECK(temp_files() == 0);
        static float small[4 * 4 * 3];
        CHECK(rp_image_write(path, 4, 4, 3, small, err, sizeof err) && !file_is(path, "previous image\n"));
    }
    CHECK(temp_files() == 0);
    return RP_TEST_END();
}
