/* The tests that run the built `raypack` command: where it is, and one run of it with stdout and
 * stderr captured together. Define CLI_RUN_TIMEOUT (seconds, a string) before including to bound
 * each run more tightly than the default, so a hang fails the check instead of blocking CTest. */
#ifndef RP_CLI_RUN_H
#define RP_CLI_RUN_H
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "rp_test.h"

#ifndef CLI_RUN_TIMEOUT
#define CLI_RUN_TIMEOUT "600"
#endif

static char exe[1024];
static char output[1 << 16];

/* Runs `PREFIX timeout T 'raypack' ARGS 2>&1` through sh (prefix: "" or a shell prefix such as
 * "ulimit -f 8;"); returns the exit status, 124 on timeout, -1 when it could not run. */
static int run_prefixed(const char *prefix, const char *args) {
    static char cmd[16384];
    int len = snprintf(cmd, sizeof cmd, "%s timeout %s '%s' %s 2>&1", prefix, CLI_RUN_TIMEOUT, exe, args);
    if (len < 0 || (size_t)len >= sizeof cmd) return -1;
    FILE *p = popen(cmd, "r");
    if (!p) return -1;
    size_t n = fread(output, 1, sizeof output - 1, p);
    output[n] = '\0';
    int st = pclose(p);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

static inline int run(const char *args) { return run_prefixed("", args); }

/* The run's exit status is `status` and its output holds `text`. */
#define EXPECT_P(prefix, args, status, text)                                                                \
    do {                                                                                                    \
        int rc_ = run_prefixed(prefix, args);                                                               \
        CHECKF(rc_ == (status) && strstr(output, (text)) != NULL,                                           \
               "raypack %s: exit %d (expected %d), output lacks '%s':\n%s", args, rc_, status, text, output); \
    } while (0)
#define EXPECT(args, status, text) EXPECT_P("", args, status, text)

/* The binary: $RP_CLI, else build/<preset>/raypack beside this test's tests/ folder. */
static bool find_exe(void) {
    const char *env = getenv("RP_CLI");
    if (env) {
        snprintf(exe, sizeof exe, "%s", env);
    } else {
        char self[900];
        ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
        if (n <= 0) return false;
        self[n] = '\0';
        char *slash = strrchr(self, '/'); /* build/<preset>/tests/test_... */
        if (!slash) return false;
        *slash = '\0';
        snprintf(exe, sizeof exe, "%s/../raypack", self);
    }
    return access(exe, X_OK) == 0;
}

#endif
