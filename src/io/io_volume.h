/* The brick-grid builder of rp_volume_data (io_volume.c), the one interface between the C loaders
 * and the OpenVDB reader (io_vdb.cpp, the only C++ file): the reader finds the grid and its active
 * voxels' box, io_volume_begin lays out the brick table over it, io_volume_set stores each active
 * voxel, io_volume_finish computes the bricks' maxima. Included from C and from C++. */
#ifndef RP_IO_VOLUME_H
#define RP_IO_VOLUME_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "raypack_io.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Sets up an empty brick grid over the inclusive index box [lo, hi] (widened by one voxel) with its
 * transform; false when out of memory or the box is too large. */
bool io_volume_begin(rp_volume_data *v, const int32_t lo[3], const int32_t hi[3], const float index_to_world[12]);
/* Stores voxel (i, j, k) inside the box given to io_volume_begin, allocating its brick on first
 * use; false when out of memory. */
bool io_volume_set(rp_volume_data *v, int32_t i, int32_t j, int32_t k, float value);
/* The bricks' maxima, the grid's maximum; false when out of memory. */
bool io_volume_finish(rp_volume_data *v);
/* Frees the arrays and the struct itself (NULL: nothing). */
void io_volume_free(rp_volume_data *v);

/* Reads float grid `grid` (NULL or "": "density" if present, else the first float grid) of the
 * OpenVDB file at path into v (zeroed by the caller) with the functions above. On failure returns
 * false with the reason (missing file, not a VDB file, no such float grid, out of memory, ...) in
 * why; v may then hold arrays for io_volume_free. Never throws. Built only with OpenVDB
 * (RP_IO_HAVE_OPENVDB); io_volume.c answers without it. */
bool io_vdb_read(const char *path, const char *grid, rp_volume_data *v, char *why, size_t why_size);

#ifdef __cplusplus
}
#endif
#endif
