/* What the MPI renderer sends between ranks, as bytes: a scene's plain data (rp_scene_data, for
 * --mpi-bcast) and finished tiles (float pixels, split into byte planes, the high ones zlib-compressed). No MPI here,
 * so the formats are tested without it. Both ends run the same build (the handshake checks it), so
 * numbers travel in the machine's own byte order. */
#ifndef RP_MPI_WIRE_H
#define RP_MPI_WIRE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "raypack_io.h"

/* Serializes every array of scene, and its animation (rp_scene_data.animation: blocks, keys,
 * visibility, `tpa` keys, the camera path, the rest copies), into one malloc'ed buffer (*out, *size;
 * the caller frees it). False when out of memory. */
bool wire_scene_pack(const rp_scene_data *scene, uint8_t **out, size_t *size);
/* Rebuilds a scene from wire_scene_pack's bytes into out (free it with rp_scene_data_free). Checks
 * every count against the bytes there are and every index against the array it points into; on a
 * bad buffer returns false with a message in err and leaves out empty. */
bool wire_scene_unpack(const uint8_t *buf, size_t size, rp_scene_data *out, char *err, size_t err_size);

/* A tile codec: zlib streams kept between tiles (setting one up costs as much as deflating a
 * small tile). One per thread. */
typedef struct wire_codec wire_codec;
/* Returns a codec, NULL when out of memory. */
wire_codec *wire_codec_new(void);
/* Frees a codec (NULL is fine). */
void wire_codec_free(wire_codec *c);
/* Upper bound of wire_tile_pack's output for n floats. */
size_t wire_tile_bound(size_t n);
/* Compresses n floats into out (cap bytes, at least wire_tile_bound(n)). The floats' bytes are
 * split into planes by significance; the low raw_planes planes (the mantissa's noise, which deflate
 * hardly shrinks) are stored as they are and the high ones (sign, exponent, top of the mantissa,
 * which neighbouring pixels repeat) deflated at zlib level 1. raw_planes 3 (fast: only the sign and
 * exponent byte is deflated) or 2 (small: 15% fewer bytes for 4x the CPU). scratch holds 4 n bytes.
 * Returns the size, 0 on failure. */
size_t wire_tile_pack(wire_codec *c, const float *px, size_t n, int raw_planes, uint8_t *scratch, uint8_t *out,
                      size_t cap);
/* Inverts wire_tile_pack: exactly n floats must come out of the size bytes at in. */
bool wire_tile_unpack(wire_codec *c, const uint8_t *in, size_t size, size_t n, uint8_t *scratch, float *px);

#endif
