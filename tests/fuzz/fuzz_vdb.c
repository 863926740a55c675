/* Fuzz harness: OpenVDB files (io_vdb.cpp, built when OpenVDB is found). OpenVDB reads files by
 * name, so the input is written to s.vdb in a folder of this process under $TMPDIR (else /tmp) and
 * rp_scene_data_load reads it as the CLI would, then the volume's invariants that the renderer
 * trusts are checked (every stored brick inside the table, densities finite and not negative).
 * The seeds (corpus/vdb) are 6-voxel density grids written by OpenVDB 10, values stored as they
 * are and zip-compressed. Without OpenVDB every input is refused, which is checked too. */
#include <math.h>
#include <sys/stat.h>
#include <unistd.h>

#include "fuzz.h"

static char dir[256];

static void remove_dir(void) {
    char p[512];
    snprintf(p, sizeof p, "%s/s.vdb", dir);
    unlink(p);
    rmdir(dir);
}

static void check_volume(const rp_volume_data *v) {
    size_t cells = (size_t)v->dims[0] * v->dims[1] * v->dims[2];
    size_t voxels = (size_t)v->brick_count * RP_VOLUME_BRICK * RP_VOLUME_BRICK * RP_VOLUME_BRICK;
    for (size_t i = 0; i < cells; i++)
        if (v->brick_slot[i] != RP_VOLUME_EMPTY && v->brick_slot[i] >= v->brick_count) abort();
    for (size_t i = 0; i < voxels; i++)
        if (!(v->density[i] >= 0.0f && v->density[i] <= v->max_density)) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (!dir[0]) {
        const char *t = getenv("TMPDIR");
        snprintf(dir, sizeof dir, "%s/rp_fuzz_vdb_%ld", t && *t ? t : "/tmp", (long)getpid());
        if (mkdir(dir, 0700) != 0) return 0;
        atexit(remove_dir);
    }
    char path[512], err[512];
    snprintf(path, sizeof path, "%s/s.vdb", dir);
    FILE *f = fopen(path, "wb");
    if (!f) return 0;
    bool written = size == 0 || fwrite(data, 1, size, f) == size;
    if (fclose(f) != 0 || !written) return 0;
    rp_scene_data s;
    bool ok = rp_scene_data_load(path, &s, err, sizeof err);
    if (getenv("RP_FUZZ_VERBOSE")) fprintf(stderr, "%s\n", ok ? "loaded" : err);
    if (ok) {
        if (s.volume) check_volume(s.volume);
        rp_scene_data_free(&s);
    } else if (!err[0]) {
        abort(); /* a refusal names its reason */
    }
    return 0;
}
