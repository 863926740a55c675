/* `mpirun raypack render --mpi` on localhost (registered as test_mpi_render when MPI is found):
 * the image of -np 1..4 (Whitted, path tracing, instant radiosity; direct and AO with -np 3), of
 * --mpi-bcast (also when only rank 0 can read the scene), PNG output, a 3-frame orbit and 3 frames
 * of BART's museum played (each rank loading it, and with --mpi-bcast) are byte-identical to the
 * single-process `raypack render` of the same camera and animation time (and to `raypack animate`'s
 * frames); a client killed mid-frame (by itself, and with kill -9 from outside at two moments, the
 * second mid-animation), hanging mid-frame or dying
 * during start-up loses no frame and changes no pixel; rank 0's death ends the job without a hang;
 * a client that never answers, one of another protocol (also protocol 1, which spoke MPI) and one
 * whose scene is broken end the job with a clear message from rank 0 within the time-out. Every
 * mpirun runs under timeout(1), so nothing can hang CI. */
#include <signal.h>
#include <stdbool.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "rp_test.h"

static char exe[1024], mpirun[1024], tmp[1024], kitchen[1024];
static char output[65536];
static double elapsed_s;

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Runs a shell command (stdout and stderr captured together), bounded by timeout(1); returns its
 * exit status (124 on time-out). */
static int run(const char *cmd) {
    char full[16384];
    snprintf(full, sizeof full, "timeout -k 5 90 %s 2>&1", cmd);
    double t0 = now_s();
    FILE *p = popen(full, "r");
    if (!p) return -1;
    size_t n = fread(output, 1, sizeof output - 1, p);
    output[n] = '\0';
    int st = pclose(p);
    elapsed_s = now_s() - t0;
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

static bool same_file(const char *a, const char *b) {
    FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
    bool same = fa && fb;
    while (same) {
        int ca = fgetc(fa), cb = fgetc(fb);
        if (ca != cb) same = false;
        if (ca == EOF || cb == EOF) break;
    }
    if (fa) fclose(fa);
    if (fb) fclose(fb);
    return same;
}

/* mpirun with the options every run needs; extra goes before the program (mpirun options). */
static int run_mpi(const char *extra, int np, const char *args) {
    char cmd[12288];
    snprintf(cmd, sizeof cmd, "'%s' --oversubscribe %s -np %d '%s' render %s", mpirun, extra, np, exe, args);
    return run(cmd);
}

static const char *SIZE = "--width 200 --height 150 --mpi-tile 32";
/* An orbit of the (animated) scene held at one time: the camera moves, the scene does not. */
static const char *ORBIT = "--orbit 60 --anim-time 1";

static void file_in_tmp(char *buf, size_t size, const char *name) { snprintf(buf, size, "%s/%s", tmp, name); }

/* A sequence's frames (PREFIX_0000.pfm...) against single-process renders of scene at the size
 * given, each at the animation time rank 0 printed for it (when it printed one) and, unless the
 * camera follows the scene's path (follow), with the camera it printed. */
static void check_frames_of(const char *scene, const char *size, const char *prefix, int frames, bool follow,
                            const char *what) {
    const char *p = output;
    for (int f = 0; f < frames; f++) {
        char tag[32], eye[128], look[128], up[128], fov[64], when[96] = "";
        snprintf(tag, sizeof tag, "frame    %d:", f);
        const char *line = strstr(p, tag);
        const char *cam = line ? strstr(line, "camera eye ") : NULL;
        CHECKF(cam && sscanf(cam, "camera eye %127s look %127s up %127s fov %63s", eye, look, up, fov) == 4,
               "%s: no camera for frame %d in:\n%s", what, f, output);
        if (!cam) return;
        const char *at = strstr(line, "anim time ");
        if (at && at < cam) snprintf(when, sizeof when, "--anim-time %.40s", at + 10);
        char *cut = strchr(when, ' ');
        if (cut) cut = strchr(cut + 1, ' ');
        if (cut) *cut = '\0'; /* "--anim-time T" */
        char saved[sizeof output];
        memcpy(saved, output, sizeof output);
        char ref[1200], got[1200], cmd[8192], camera[700] = "";
        snprintf(ref, sizeof ref, "%s/%s_ref_%d.pfm", tmp, prefix, f);
        snprintf(got, sizeof got, "%s/%s_%04d.pfm", tmp, prefix, f);
        if (!follow) snprintf(camera, sizeof camera, "--eye %s --look %s --up %s --fov %s", eye, look, up, fov);
        snprintf(cmd, sizeof cmd, "'%s' render '%s' %s %s %s -o '%s' --quiet", exe, scene, size, when, camera, ref);
        CHECK(run(cmd) == 0);
        CHECKF(same_file(ref, got), "%s: frame %d differs from the single process (%s, %s: %s)", what, f, got, ref, cmd);
        memcpy(output, saved, sizeof output);
        p = cam;
    }
}

/* The orbit's (or the animation's) frames of the kitchen at 200x150. */
static void check_frames(const char *prefix, int frames, bool follow, const char *what) {
    check_frames_of(kitchen, "--width 200 --height 150", prefix, frames, follow, what);
}

/* A -np 3 sequence of frames (an orbit of the scene held at one time, or its animation: play),
 * where the client `rank` is killed with SIGKILL from outside when rank 0 prints a line starting
 * with `trigger`: the job still writes every frame, each identical. */
static void outside_kill(const char *trigger, int rank, int frames, bool play, const char *prefix) {
    char got[1200], args[8192], pidline[64], name[64];
    snprintf(name, sizeof name, "%s.pfm", prefix);
    file_in_tmp(got, sizeof got, name);
    snprintf(args, sizeof args,
             "timeout -k 5 90 '%s' --oversubscribe --enable-recovery -np 3 '%s' render '%s' --mpi %s --frames %d "
             "%s -o '%s' --mpi-timeout 2 2>&1",
             mpirun, exe, kitchen, SIZE, frames, play ? "" : ORBIT, got);
    snprintf(pidline, sizeof pidline, "client   rank %d: pid %%d", rank);
    FILE *p = popen(args, "r");
    CHECK(p != NULL);
    if (!p) return;
    size_t len = 0;
    char line[4096];
    int killed = 0, pid = 0;
    while (fgets(line, sizeof line, p)) {
        int v;
        if (!pid && sscanf(line, pidline, &v) == 1 && v > 1) pid = v;
        if (!killed && pid && strncmp(line, trigger, strlen(trigger)) == 0) killed = kill(pid, SIGKILL) == 0;
        size_t n = strlen(line);
        if (len + n < sizeof output) {
            memcpy(output + len, line, n);
            len += n;
        }
    }
    output[len] = '\0';
    int st = pclose(p);
    char lost[64];
    snprintf(lost, sizeof lost, "rank %d (pid", rank);
    CHECKF(killed && WIFEXITED(st) && WEXITSTATUS(st) == 0 && strstr(output, lost),
           "kill -9 from outside at '%s': killed %d, status %d:\n%s", trigger, killed, st, output);
    check_frames(prefix, frames, play, play ? "animation with a client killed from outside"
                                             : "orbit with a client killed from outside");
}

int main(void) {
    const char *env = getenv("RP_CLI");
    if (env) snprintf(exe, sizeof exe, "%s", env);
    else {
        char self[900];
        ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
        if (n > 0) {
            self[n] = '\0';
            char *slash = strrchr(self, '/');
            if (slash) *slash = '\0';
            snprintf(exe, sizeof exe, "%s/../raypack", self);
        }
    }
    snprintf(mpirun, sizeof mpirun, "%s", getenv("RP_MPIEXEC") ? getenv("RP_MPIEXEC") : "mpirun");
    const char *dir = getenv("RP_TEST_TMP");
    snprintf(tmp, 900, "%s", dir ? dir : "/tmp/raypack_test_mpi");
    mkdir(tmp, 0777);
    char buf[1024], args[8192], ref[1200], got[1200];
    /* BART's kitchen; in the sanitized build, where every rank's load is slow, the smaller museum */
    const char *k = rp_test_scene(rp_test_sanitized() ? "bart_museum5.tar.gz" : "bart_kitchen.tar.gz", buf, sizeof buf);
    CHECK(k != NULL && access(exe, X_OK) == 0);
    if (!k || access(exe, X_OK) != 0) return RP_TEST_END();
    snprintf(kitchen, sizeof kitchen, "%s", k);

    /* The single-process references. */
    file_in_tmp(ref, sizeof ref, "ref.pfm");
    snprintf(args, sizeof args, "'%s' render '%s' --width 200 --height 150 -o '%s' --quiet", exe, kitchen, ref);
    CHECK(run(args) == 0);
    char refpng[1200];
    file_in_tmp(refpng, sizeof refpng, "ref.png");
    snprintf(args, sizeof args, "'%s' render '%s' --width 200 --height 150 -o '%s' --quiet", exe, kitchen, refpng);
    CHECK(run(args) == 0);

    /* -np 1 (rank 0 alone) .. 4 (three clients on two cores). */
    for (int np = 1; np <= 4; np++) {
        char name[32];
        snprintf(name, sizeof name, "np%d.pfm", np);
        file_in_tmp(got, sizeof got, name);
        snprintf(args, sizeof args, "'%s' --mpi %s -o '%s'", kitchen, SIZE, got);
        int rc = run_mpi("", np, args);
        CHECKF(rc == 0 && same_file(ref, got), "-np %d: exit %d, image %s:\n%s", np, rc,
               same_file(ref, got) ? "identical" : "differs", output);
        if (np > 1) CHECKF(strstr(output, "share    frame 0: rank 1"), "-np %d reports no shares:\n%s", np, output);
    }
    /* The physically based integrators: path and instant radiosity for -np 1..4 (IR's tiles read a
     * margin for its filter), direct and AO with -np 3, each against its single process. */
    static const char *const pbr[][2] = {{"path", "--spp 2"}, {"ir", "--ir-vpls 8"}, {"direct", ""}, {"ao", "--spp 2"}};
    for (int i = 0; i < 4; i++) {
        char pref[1200], name[64];
        snprintf(name, sizeof name, "ref_%s.pfm", pbr[i][0]);
        file_in_tmp(pref, sizeof pref, name);
        snprintf(args, sizeof args, "'%s' render '%s' --width 200 --height 150 --integrator %s %s -o '%s' --quiet", exe,
                 kitchen, pbr[i][0], pbr[i][1], pref);
        CHECK(run(args) == 0);
        for (int np = i < 2 ? 1 : 3; np <= (i < 2 ? 4 : 3); np++) {
            snprintf(name, sizeof name, "%s_np%d.pfm", pbr[i][0], np);
            file_in_tmp(got, sizeof got, name);
            snprintf(args, sizeof args, "'%s' --mpi %s --integrator %s %s -o '%s'", kitchen, SIZE, pbr[i][0], pbr[i][1],
                     got);
            int rc = run_mpi("", np, args);
            CHECKF(rc == 0 && same_file(pref, got), "--integrator %s -np %d: exit %d, image %s:\n%s", pbr[i][0], np, rc,
                   same_file(pref, got) ? "identical" : "differs", output);
        }
    }
    file_in_tmp(got, sizeof got, "np3.png");
    snprintf(args, sizeof args, "'%s' --mpi %s -o '%s' --mpi-tile 48", kitchen, SIZE, got);
    CHECKF(run_mpi("", 3, args) == 0 && same_file(refpng, got), "PNG through -np 3 differs:\n%s", output);

    /* --mpi-bcast: every rank can read the file, then only rank 0 (the clients run in a folder
     * where the scene's path names nothing). */
    file_in_tmp(got, sizeof got, "bcast.pfm");
    snprintf(args, sizeof args, "'%s' --mpi --mpi-bcast --mpi-compress small %s -o '%s'", kitchen, SIZE, got);
    CHECKF(run_mpi("", 3, args) == 0 && same_file(ref, got) && strstr(output, "scene broadcast"),
           "--mpi-bcast:\n%s", output);
    char a[1100], b[1100], link[1200];
    file_in_tmp(a, sizeof a, "rank0");
    file_in_tmp(b, sizeof b, "others");
    mkdir(a, 0777);
    mkdir(b, 0777);
    snprintf(link, sizeof link, "%s/scene.tar.gz", a);
    unlink(link);
    CHECK(symlink(kitchen, link) == 0);
    char broken[1200];
    snprintf(broken, sizeof broken, "%s/scene.tar.gz", b);
    FILE *f = fopen(broken, "wb");
    if (f) {
        fputs("this is not a tar archive\n", f);
        fclose(f);
    }
    file_in_tmp(got, sizeof got, "bcast0.pfm");
    snprintf(args, sizeof args,
             "'%s' --oversubscribe -np 1 --wdir '%s' '%s' render scene.tar.gz --mpi --mpi-bcast %s -o '%s' : "
             "-np 2 --wdir '%s' '%s' render scene.tar.gz --mpi --mpi-bcast %s -o '%s'",
             mpirun, a, exe, SIZE, got, b, exe, SIZE, got);
    CHECKF(run(args) == 0 && same_file(ref, got), "--mpi-bcast with a scene only rank 0 can read:\n%s", output);
    /* Without --mpi-bcast the clients' broken file is an error on rank 0, naming rank and file. */
    snprintf(args, sizeof args,
             "'%s' --oversubscribe -np 1 --wdir '%s' '%s' render scene.tar.gz --mpi %s -o '%s' --mpi-timeout 20 : "
             "-np 2 --wdir '%s' '%s' render scene.tar.gz --mpi %s -o '%s' --mpi-timeout 20",
             mpirun, a, exe, SIZE, got, b, exe, SIZE, got);
    int rc = run(args);
    CHECKF(rc != 0 && rc != 124 && strstr(output, "rank 1") && strstr(output, "has no scene: scene.tar.gz"),
           "a client's broken scene: exit %d:\n%s", rc, output);

    /* A 3-frame orbit: every frame equals the single process at that frame's camera. */
    file_in_tmp(got, sizeof got, "orbit.pfm");
    snprintf(args, sizeof args, "'%s' --mpi %s --frames 3 %s -o '%s'", kitchen, SIZE, ORBIT, got);
    CHECKF(run_mpi("", 3, args) == 0 && strstr(output, "every frame at time 1"), "orbit:\n%s", output);
    check_frames("orbit", 3, false, "orbit");
    /* An animated scene without --anim-time plays: an orbit there is refused. */
    snprintf(args, sizeof args, "'%s' --mpi %s --frames 3 --orbit 60 -o '%s'", kitchen, SIZE, got);
    rc = run_mpi("", 3, args);
    CHECKF(rc != 0 && rc != 124 && strstr(output, "--orbit moves the camera of a still scene"),
           "--orbit on an animation: exit %d:\n%s", rc, output);
    /* ... and --anim-time on a still scene (the built-in room) is refused too */
    rc = run_mpi("", 1, "--mpi --anim-time 1 --width 16 --height 16 -o /dev/null.png");
    CHECKF(rc != 0 && rc != 124 && strstr(output, "--anim-time: the scene is not animated"),
           "--anim-time on a still scene: exit %d:\n%s", rc, output);
    /* The loader's warnings reach stderr once, from rank 0 (they were dropped): a usemtl naming no
     * material */
    file_in_tmp(got, sizeof got, "usemtl.obj");
    FILE *uf = fopen(got, "w");
    CHECK(uf != NULL);
    if (uf) {
        fputs("v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl nosuch\nf 1 2 3\n", uf);
        fclose(uf);
        snprintf(args, sizeof args, "'%s' --mpi --width 16 --height 16 -o '%s/usemtl.png'", got, tmp);
        rc = run_mpi("", 2, args);
        const char *w1 = strstr(output, "usemtl.obj:4: warning: usemtl 'nosuch'");
        CHECKF(rc == 0 && w1 && !strstr(w1 + 1, "usemtl.obj:4: warning"), "the loader's warning once: exit %d:\n%s", rc,
               output);
    }
    /* A camera with no frame is refused as `raypack render` refuses it, not rendered (it wrote an
     * image with exit 0): an up along the view, and a --to-eye path through the look-at point, whose
     * middle frame has no view direction. */
    rc = run_mpi("", 2, "--mpi --eye 0,0,0 --look 0,1,0 --up 0,1,0 --width 16 --height 16 -o /dev/null.png");
    CHECKF(rc == 2 && strstr(output, "--eye, --look and --up: the up vector is parallel to the view direction"),
           "an up along the view: exit %d:\n%s", rc, output);
    file_in_tmp(got, sizeof got, "through.png");
    snprintf(args, sizeof args, "--mpi --eye 1,1,4 --to-eye -1,1,-4 --look 0,1,0 --frames 3 --width 16 --height 16 -o '%s'",
             got);
    rc = run_mpi("", 2, args);
    CHECKF(rc != 0 && rc != 124 && strstr(output, "the eye is the look-at point") && strstr(output, "frame 1's camera"),
           "a camera path through the look-at point: exit %d:\n%s", rc, output);

    /* BART's museum played for 3 frames with -np 3, each rank loading the file and with
     * --mpi-bcast (the animation on the wire): every frame equals `raypack render --anim-time T` at
     * the time rank 0 printed, with the scene's own (moving) camera, and `raypack animate`'s frame. */
    char museum_buf[1024];
    const char *museum = rp_test_scene("bart_museum5.tar.gz", museum_buf, sizeof museum_buf);
    CHECK(museum != NULL);
    if (museum) {
        char pattern[1200], mine[1200], theirs[1200];
        static const char *const MSIZE = "--width 96 --height 72";
        file_in_tmp(pattern, sizeof pattern, "museum_anim_%04d.pfm");
        snprintf(args, sizeof args, "'%s' animate '%s' --frames 3 %s -o '%s' --quiet", exe, museum, MSIZE, pattern);
        CHECK(run(args) == 0);
        static const char *const how[] = {"", "--mpi-bcast"};
        for (int i = 0; i < 2; i++) {
            const char *prefix = i ? "museum_bcast" : "museum";
            char name[64];
            snprintf(name, sizeof name, "%s.pfm", prefix);
            file_in_tmp(got, sizeof got, name);
            snprintf(args, sizeof args, "'%s' --mpi %s %s --mpi-tile 16 --frames 3 -o '%s'", museum, how[i], MSIZE, got);
            rc = run_mpi("", 3, args);
            CHECKF(rc == 0 && strstr(output, "3 frames of the animation") && strstr(output, "anim time 5 "),
                   "museum animation %s: exit %d:\n%s", how[i], rc, output);
            check_frames_of(museum, MSIZE, prefix, 3, true, i ? "museum animation, --mpi-bcast" : "museum animation");
            for (int j = 0; j < 3; j++) {
                snprintf(mine, sizeof mine, "%s/%s_%04d.pfm", tmp, prefix, j);
                snprintf(theirs, sizeof theirs, pattern, j);
                CHECKF(same_file(mine, theirs), "museum animation %s: frame %d differs from raypack animate's", how[i], j);
            }
        }
        /* the animation moved: its first and last frames differ */
        snprintf(mine, sizeof mine, "%s/museum_0000.pfm", tmp);
        snprintf(theirs, sizeof theirs, "%s/museum_0002.pfm", tmp);
        CHECK(!same_file(mine, theirs));
    }

    /* Volumes with their flags, loaded by every rank and broadcast (format 3 carries the volume; a
     * broadcast scene lost it before): the cloud (when OpenVDB was found) and a --medium-box. */
    {
        char vbuf[1024], vref[1200], vargs[4096];
        const char *cloud = rp_test_scene("volume_wdas_cloud/wdas_cloud_sixteenth.vdb", vbuf, sizeof vbuf);
        const char *box = "--medium-box 100,0,100,400,300,400 --albedo 0.7,0.8,0.9 --hg-g 0.4";
        const char *vol[2][2] = {{cloud, "--density-scale 3 --albedo 0.8 --hg-g 0.3"}, {NULL, box}};
        char cornell[1024];
        const char *cb = rp_test_scene("cornell_box/cornell_box.obj", cornell, sizeof cornell);
        vol[1][0] = cb;
        for (int i = 0; i < 2; i++) {
            if (!vol[i][0]) continue;
            file_in_tmp(vref, sizeof vref, i ? "vol_box_ref.pfm" : "vol_cloud_ref.pfm");
            snprintf(vargs, sizeof vargs, "'%s' render '%s' --integrator path --spp 1 --width 48 --height 40 %s -o '%s' --quiet",
                     exe, vol[i][0], vol[i][1], vref);
            if (run(vargs) != 0) {
                CHECKF(i == 0 && strstr(output, "without OpenVDB"), "volume reference:\n%s", output);
                continue;
            }
            for (int bc = 0; bc < 2; bc++) {
                file_in_tmp(got, sizeof got, bc ? "vol_bcast.pfm" : "vol.pfm");
                snprintf(args, sizeof args, "'%s' --mpi %s --integrator path --spp 1 --width 48 --height 40 --mpi-tile 16 %s -o '%s'",
                         vol[i][0], bc ? "--mpi-bcast" : "", vol[i][1], got);
                int vrc = run_mpi("", 3, args);
                CHECKF(vrc == 0 && same_file(vref, got), "%s%s -np 3: exit %d, the image differs:\n%s",
                       i ? "a --medium-box" : "the cloud", bc ? " with --mpi-bcast" : "", vrc, output);
            }
        }
    }

    /* A client kills itself (SIGKILL) holding two tiles mid-frame: they go to the others. */
    file_in_tmp(got, sizeof got, "killed.pfm");
    snprintf(args, sizeof args, "'%s' --mpi %s -o '%s' --mpi-timeout 2", kitchen, SIZE, got);
    rc = run_mpi("--enable-recovery -x RAYPACK_MPI_TEST_KILL=2:3", 4, args);
    CHECKF(rc == 0 && same_file(ref, got) && strstr(output, "rank 2 (pid") && strstr(output, "to the others") &&
           elapsed_s < 40.0, "killed client: exit %d after %.1f s:\n%s", rc, elapsed_s, output);
    /* ... or dies during start-up, while rank 0 sends it the scene: it is left out. */
    file_in_tmp(got, sizeof got, "died_at_start.pfm");
    snprintf(args, sizeof args, "'%s' --mpi --mpi-bcast %s -o '%s' --mpi-timeout 2", kitchen, SIZE, got);
    rc = run_mpi("--enable-recovery -x RAYPACK_MPI_TEST_DIE_AT_START=1", 3, args);
    CHECKF(rc == 0 && same_file(ref, got) && strstr(output, "rank 1 (pid") && strstr(output, "during start-up") &&
           elapsed_s < 40.0, "client dead at start-up: exit %d after %.1f s:\n%s", rc, elapsed_s, output);
    /* ... or hangs there, alive: the job still ends, with the image. */
    file_in_tmp(got, sizeof got, "hung.pfm");
    snprintf(args, sizeof args, "'%s' --mpi %s -o '%s' --mpi-timeout 2", kitchen, SIZE, got);
    rc = run_mpi("--enable-recovery -x RAYPACK_MPI_TEST_HANG=1:2", 3, args);
    CHECKF(rc == 0 && same_file(ref, got) && strstr(output, "rank 1 (pid") && elapsed_s < 40.0,
           "hanging client: exit %d after %.1f s:\n%s", rc, elapsed_s, output);

    /* kill -9 from outside: as soon as rank 0 has named its clients (frame 0 starting), and after
     * frame 1 of a sequence (tiles in flight both ways). Rank 0 sees the connection close and hands
     * the tiles on; every frame equals the single process. */
    outside_kill("client   rank 2:", 2, 3, false, "orbitk");
    outside_kill("frame    1:", 1, 4, true, "animk1"); /* mid-animation */

    /* Rank 0 dies mid-frame: the job ends (under --enable-recovery the clients give up after 4
     * time-outs of silence), nothing hangs. */
    file_in_tmp(got, sizeof got, "server_killed.pfm");
    snprintf(args, sizeof args, "'%s' --mpi %s -o '%s' --mpi-timeout 2", kitchen, SIZE, got);
    rc = run_mpi("--enable-recovery -x RAYPACK_MPI_TEST_KILL=0:5", 3, args);
    /* (mpirun --enable-recovery exits 0 even so: the missing image is what tells) */
    CHECKF(rc != 124 && elapsed_s < 40.0 && access(got, F_OK) != 0 && strstr(output, "giving up"),
           "rank 0 killed: exit %d after %.1f s:\n%s", rc, elapsed_s, output);

    /* A client that never answers, and one of another protocol: rank 0 says so within the time-out. */
    file_in_tmp(got, sizeof got, "never.pfm");
    snprintf(args, sizeof args, "'%s' --mpi %s -o '%s' --mpi-timeout 2", kitchen, SIZE, got);
    rc = run_mpi("-x RAYPACK_MPI_TEST_STALL=2", 3, args);
    CHECKF(rc != 0 && rc != 124 && strstr(output, "rank 2 did not answer within 2.0 s") && elapsed_s < 30.0,
           "silent client: exit %d after %.1f s:\n%s", rc, elapsed_s, output);
    /* (protocol 2: the one before the animation went on the wire) */
    rc = run_mpi("-x RAYPACK_MPI_TEST_PROTOCOL=1:2", 3, args);
    CHECKF(rc != 0 && rc != 124 && strstr(output, "rank 1 (pid") && strstr(output, "protocol 2 ") &&
           strstr(output, "run the same build on every rank"), "another protocol: exit %d:\n%s", rc, output);
    /* a client of protocol 1 (all over MPI) says hello there: rank 0 names it */
    rc = run_mpi("-x RAYPACK_MPI_TEST_PROTOCOL1=2", 3, args);
    CHECKF(rc != 0 && rc != 124 && strstr(output, "rank 2 (pid") && strstr(output, "MPI protocol 1;") &&
           strstr(output, "run the same build on every rank") && elapsed_s < 30.0, "protocol 1: exit %d:\n%s", rc,
           output);
    return RP_TEST_END();
}
