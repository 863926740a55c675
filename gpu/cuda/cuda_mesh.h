/* A scene's triangles with a camera and a light, in one raw file that the GPU programs read
 * (gpu_mesh_dump writes it from any scene file raypack loads). The GPU machine gets a copy of the
 * working tree but not the libraries behind the loaders (assimp, libarchive, ...), so the programs
 * that run there link the core alone and read this instead of the scene.
 *
 * Layout, little endian: the 8 bytes "RPMESH1\n"; uint64 vertex_count, triangle_count; float eye[3],
 * look[3], up[3], fov_deg, light[3]; vertex_count * 3 floats; triangle_count * 3 uint32 indices. */
#ifndef RP_CUDA_MESH_H
#define RP_CUDA_MESH_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct cuda_mesh {
    uint64_t vertex_count, triangle_count;
    float eye[3], look[3], up[3], fov_deg, light[3];
    float *positions;
    uint32_t *indices;
} cuda_mesh;

static const char cuda_mesh_magic[8] = {'R', 'P', 'M', 'E', 'S', 'H', '1', '\n'};

static inline void cuda_mesh_free(cuda_mesh *m) {
    free(m->positions);
    free(m->indices);
    memset(m, 0, sizeof *m);
}

static inline bool cuda_mesh_write(const char *path, const cuda_mesh *m) {
    FILE *f = fopen(path, "wb");
    if (!f) return false;
    bool ok = fwrite(cuda_mesh_magic, 8, 1, f) == 1 && fwrite(&m->vertex_count, 8, 1, f) == 1 &&
              fwrite(&m->triangle_count, 8, 1, f) == 1 && fwrite(m->eye, 4, 3, f) == 3 && fwrite(m->look, 4, 3, f) == 3 &&
              fwrite(m->up, 4, 3, f) == 3 && fwrite(&m->fov_deg, 4, 1, f) == 1 && fwrite(m->light, 4, 3, f) == 3 &&
              fwrite(m->positions, 12, m->vertex_count, f) == m->vertex_count &&
              fwrite(m->indices, 12, m->triangle_count, f) == m->triangle_count;
    return fclose(f) == 0 && ok;
}

/* Reads a mesh file; false with a reason in err. Indices are checked against the vertex count. */
static inline bool cuda_mesh_read(const char *path, cuda_mesh *m, char *err, size_t err_size) {
    memset(m, 0, sizeof *m);
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(err, err_size, "%s: cannot open", path);
        return false;
    }
    char magic[8];
    bool ok = fread(magic, 8, 1, f) == 1 && memcmp(magic, cuda_mesh_magic, 8) == 0 &&
              fread(&m->vertex_count, 8, 1, f) == 1 && fread(&m->triangle_count, 8, 1, f) == 1 &&
              m->vertex_count < (1ull << 32) && m->triangle_count < (1ull << 32) && fread(m->eye, 4, 3, f) == 3 &&
              fread(m->look, 4, 3, f) == 3 && fread(m->up, 4, 3, f) == 3 && fread(&m->fov_deg, 4, 1, f) == 1 &&
              fread(m->light, 4, 3, f) == 3;
    if (ok) {
        m->positions = malloc((m->vertex_count ? m->vertex_count : 1) * 12 + 4);
        m->indices = malloc((m->triangle_count ? m->triangle_count : 1) * 12);
        ok = m->positions && m->indices && fread(m->positions, 12, m->vertex_count, f) == m->vertex_count &&
             fread(m->indices, 12, m->triangle_count, f) == m->triangle_count;
    }
    fclose(f);
    for (uint64_t i = 0; ok && i < 3 * m->triangle_count; i++) ok = m->indices[i] < m->vertex_count;
    if (!ok) {
        snprintf(err, err_size, "%s: not a complete RPMESH1 file", path);
        cuda_mesh_free(m);
    }
    return ok;
}

#endif
