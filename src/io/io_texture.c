/* Texture images for materials: PPM (P3 and P6) decoded here, PNG, JPEG, TGA and BMP by stb_image.
 * All end up 8-bit RGB, top row first. stb_image trusts its input more than a loader may (fuzzing
 * found a heap overflow in its 16-bit PNM path, one in its JPEG Huffman tables and an int overflow
 * in its JPEG DC prediction): only its PNG, JPEG, TGA and BMP decoders are compiled (TGA and BMP
 * because OBJ models ship them: Crytek's Sponza, 3ds Max exports), JPEG Huffman tables are checked
 * here first and a JPEG's DC coefficients by a dry run of stb's own parser, and the declared size
 * is capped before it allocates. */
#include <math.h>
#include <stdio.h>

#include "io/io_internal.h"

/* stb_image is third-party code: compiled here once, static, without the project's warnings (the
 * unused-function one stays off to the end of the file, where GCC reports it). */
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wmissing-prototypes"
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#pragma GCC diagnostic ignored "-Wswitch-enum"
#pragma GCC diagnostic ignored "-Wimplicit-fallthrough"
#pragma GCC diagnostic ignored "-Wdouble-promotion"
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#define STBI_NO_STDIO
#define STBI_NO_HDR
#define STBI_NO_LINEAR
#define STBI_ONLY_PNG
#define STBI_ONLY_JPEG
#define STBI_ONLY_TGA
#define STBI_ONLY_BMP
/* stb's allocations are the loaders' (io_alloc.c), so a test can refuse them too */
#define STBI_MALLOC(size) io_malloc(size)
#define STBI_REALLOC(p, size) io_realloc(p, size)
#define STBI_FREE(p) free(p)
#include <stb/stb_image.h>
#pragma GCC diagnostic pop

/* Reads one header field of a PPM (skipping whitespace and # comments). */
static const char *ppm_field(const char *p, const char *end, int64_t *v) {
    for (;;) {
        while (p < end && (io_is_space(*p) || *p == '\n')) p++;
        if (p < end && *p == '#') {
            while (p < end && *p != '\n') p++;
            continue;
        }
        break;
    }
    if (p >= end) return NULL;
    return io_parse_int(p, v);
}

/* Decodes a P3/P6 PPM into rgb; returns NULL with a message in why. */
static uint8_t *ppm_decode(const char *data, size_t size, int32_t *w, int32_t *h, const char **why) {
    const char *p = data + 2, *end = data + size;
    int64_t width, height, maxval;
    bool ascii = data[1] == '3';
    if (!(p = ppm_field(p, end, &width)) || !(p = ppm_field(p, end, &height)) ||
        !(p = ppm_field(p, end, &maxval))) {
        *why = "bad PPM header";
        return NULL;
    }
    if (width <= 0 || height <= 0 || width > 65536 || height > 65536 || maxval <= 0 || maxval > 65535) {
        *why = "PPM size or maximum value out of range";
        return NULL;
    }
    size_t n = (size_t)width * (size_t)height * 3;
    /* Check the data can be there before allocating for it: P6 stores n samples, P3 at least 2n bytes. */
    size_t left = p < end ? (size_t)(end - p) : 0;
    if ((ascii && left / 2 < n) || (!ascii && left < n * (maxval > 255 ? 2 : 1) + 1)) {
        *why = ascii ? "truncated or bad P3 pixel data" : "truncated P6 pixel data";
        return NULL;
    }
    uint8_t *rgb = io_malloc(n);
    if (!rgb) {
        *why = "out of memory";
        return NULL;
    }
    if (ascii) {
        for (size_t i = 0; i < n; i++) {
            int64_t v;
            if (!(p = ppm_field(p, end, &v)) || v < 0 || v > maxval) {
                free(rgb);
                *why = "truncated or bad P3 pixel data";
                return NULL;
            }
            rgb[i] = (uint8_t)((v * 255 + maxval / 2) / maxval);
        }
    } else {
        p++; /* the single whitespace byte after maxval */
        size_t bpc = maxval > 255 ? 2 : 1;
        if (p > end || (size_t)(end - p) < n * bpc) {
            free(rgb);
            *why = "truncated P6 pixel data";
            return NULL;
        }
        const uint8_t *s = (const uint8_t *)p;
        if (maxval == 255) { /* the common case: the samples as they are */
            memcpy(rgb, s, n);
            n = 0;
        }
        for (size_t i = 0; i < n; i++) {
            int64_t v = bpc == 2 ? (int64_t)s[2 * i] << 8 | s[2 * i + 1] : s[i];
            if (v > maxval) v = maxval;
            if (maxval != 255) v = (v * 255 + maxval / 2) / maxval;
            rgb[i] = (uint8_t)v;
        }
    }
    *w = (int32_t)width;
    *h = (int32_t)height;
    return rgb;
}

/* True unless a JPEG's DHT segment declares a table of more than 256 codes or runs past its
 * segment (stb_image (2022-09) writes such counts past its 257-entry arrays), or a scan decodes with
 * a Huffman table no DHT defined before it (stb then reads its never-written table: indices of
 * 16777346 into a 256-entry array, found by the texture fuzzer; a baseline scan decodes AC
 * coefficients whatever its Se says). Walks the markers up to the end,
 * skipping entropy-coded data (progressive files have tables between scans). */
static bool jpeg_tables_ok(const uint8_t *d, size_t n) {
    bool defined[2][4] = {{false}}; /* [DC, AC][table id] */
    bool progressive = false;
    size_t i = 0; /* stb takes fill bytes (0xFF) before SOI, so the walk starts at 0 */
    while (i + 4 <= n) {
        if (d[i] != 0xFF) {
            i++; /* entropy-coded data: look for the next marker */
            continue;
        }
        uint8_t m = d[i + 1];
        if (m == 0x00 || m == 0xFF || (m >= 0xD0 && m <= 0xD8) || m == 0x01) {
            i += m == 0xFF ? 1 : 2; /* stuffing, fill, restart markers, SOI: no length */
            continue;
        }
        if (m == 0xD9) return true; /* EOI */
        size_t len = (size_t)d[i + 2] << 8 | d[i + 3];
        if (len < 2) return false;
        size_t seg = i + 4, seg_end = i + 2 + len;
        if (seg_end > n) seg_end = n; /* truncated: stb reads zeros past the end */
        if (m == 0xC2) progressive = true;
        if (m == 0xC4) {
            size_t j = seg;
            while (j < seg_end) {
                if (j + 17 > seg_end) return false;
                unsigned total = 0;
                for (int k = 0; k < 16; k++) total += d[j + 1 + (size_t)k];
                if (total > 256) return false;
                unsigned tc = d[j] >> 4, th = d[j] & 15u;
                if (tc > 1 || th > 3) return false;
                defined[tc][th] = true;
                j += 17 + total;
            }
        }
        if (m == 0xDA) { /* SOS: the tables each component's scan decodes with */
            if (seg >= seg_end) return false;
            size_t ns = d[seg];
            if (ns < 1 || ns > 4 || seg + 1 + 2 * ns + 2 > seg_end) return false;
            unsigned ss = d[seg + 1 + 2 * ns], se = d[seg + 2 + 2 * ns];
            for (size_t c = 0; c < ns; c++) {
                unsigned t = d[seg + 2 + 2 * c], td = t >> 4, ta = t & 15u;
                if (td > 3 || ta > 3) return false;
                if (ss == 0 && !defined[0][td]) return false; /* DC coefficients */
                /* AC coefficients: a baseline scan always has them (stb takes Se as 63 there) */
                if ((se > 0 || !progressive) && !defined[1][ta]) return false;
            }
        }
        i = i + 2 + len;
    }
    return true;
}

/* A DC coefficient stb_image cannot hold: stb stores dequantised coefficients as shorts, and
 * computes them in int as dc * dequant[0] (baseline) or dc << Al (progressive), with dc summed over
 * every block since the last restart. Corrupt data (long runs of the largest DC difference, or the
 * zeros stb feeds itself past the end of the data) grows dc until that int overflows (undefined
 * behaviour, stb_image.h:2197, found by the texture fuzzer). Real 8-bit JPEGs stay within about
 * +-1024 after dequantisation. */
static bool jpeg_dc_out_of_range(int dc, int scale) {
    return dc < -32768 || dc > 32767 || (dc < 0 ? -dc : dc) * scale > 32767; /* the first bound keeps the product in int */
}

/* stb_image takes bits it may not have once a marker ends the data (its fast AC path, its
 * extend-receive): its count of bits goes negative, and a refill at -8 or below shifts an int by
 * 32 or more (undefined, stb_image.h:2065, found by the texture fuzzer). True when the next refill
 * would; checked before each call into stb's bit reader. */
static bool jpeg_bits_broken(const stbi__jpeg *j) { return j->code_bits <= -8; }

/* stbi__jpeg_decode_block without its stores and IDCT: the same bits, the same DC prediction;
 * returns 0 where stb fails (it then stops), -1 for a DC coefficient out of range, -2 for a count
 * of bits stb would break on (jpeg_bits_broken), else 1. */
static int jpeg_check_block(stbi__jpeg *j, stbi__huffman *hdc, stbi__huffman *hac, stbi__int16 *fac, int b,
                            int dequant) {
    if (jpeg_bits_broken(j)) return -2;
    if (j->code_bits < 16) stbi__grow_buffer_unsafe(j);
    int t = stbi__jpeg_huff_decode(j, hdc);
    if (t < 0 || t > 15) return 0;
    int diff = t ? stbi__extend_receive(j, t) : 0;
    int dc = j->img_comp[b].dc_pred + diff; /* |dc_pred| <= 32767 here: no overflow */
    j->img_comp[b].dc_pred = dc;
    if (jpeg_dc_out_of_range(dc, dequant)) return -1;
    int k = 1;
    do {
        if (jpeg_bits_broken(j)) return -2;
        if (j->code_bits < 16) stbi__grow_buffer_unsafe(j);
        int c = (int)((j->code_buffer >> (32 - FAST_BITS)) & ((1 << FAST_BITS) - 1));
        int r = fac[c];
        if (r) {
            k += (r >> 4) & 15;
            int s = r & 15;
            j->code_buffer <<= s;
            j->code_bits -= s;
            k++;
        } else {
            int rs = stbi__jpeg_huff_decode(j, hac);
            if (rs < 0) return 0;
            int s = rs & 15;
            r = rs >> 4;
            if (s == 0) {
                if (rs != 0xf0) break;
                k += 16;
            } else {
                k += r;
                (void)stbi__extend_receive(j, s);
                k++;
            }
        }
    } while (k < 64);
    return 1;
}

/* stbi__jpeg_decode_block_prog_dc likewise (first DC scans only: refinements add one bit). */
static int jpeg_check_block_prog_dc(stbi__jpeg *j, stbi__huffman *hdc, int b) {
    if (j->spec_end != 0) return 0;
    if (jpeg_bits_broken(j)) return -2;
    if (j->code_bits < 16) stbi__grow_buffer_unsafe(j);
    if (j->succ_high != 0) {
        (void)stbi__jpeg_get_bit(j);
        return 1;
    }
    int t = stbi__jpeg_huff_decode(j, hdc);
    if (t < 0 || t > 15) return 0;
    int dc = j->img_comp[b].dc_pred + (t ? stbi__extend_receive(j, t) : 0);
    j->img_comp[b].dc_pred = dc;
    return jpeg_dc_out_of_range(dc, 1 << j->succ_low) ? -1 : 1;
}

/* stbi__jpeg_decode_block_prog_ac likewise: the same bits read, the coefficients kept only as which
 * of the block's 64 are not zero (*nz, bit = position in the block), for the refinement scans read
 * a bit for each coefficient that is not zero. 0, -2 or 1 as above. */
static int jpeg_check_block_prog_ac(stbi__jpeg *j, stbi__huffman *hac, stbi__int16 *fac, uint64_t *nz) {
    if (j->spec_start == 0) return 0;
    int k = j->spec_start;
    if (j->succ_high == 0) {
        int shift = j->succ_low;
        if (j->eob_run) {
            --j->eob_run;
            return 1;
        }
        do {
            if (jpeg_bits_broken(j)) return -2;
            if (j->code_bits < 16) stbi__grow_buffer_unsafe(j);
            int c = (int)((j->code_buffer >> (32 - FAST_BITS)) & ((1 << FAST_BITS) - 1));
            int r = fac[c], v;
            unsigned zig;
            if (r) { /* fast-AC path */
                k += (r >> 4) & 15;
                int sz = r & 15;
                j->code_buffer <<= sz;
                j->code_bits -= sz;
                zig = stbi__jpeg_dezigzag[k++];
                v = (short)((r >> 8) * (1 << shift));
            } else {
                if (jpeg_bits_broken(j)) return -2;
                int rs = stbi__jpeg_huff_decode(j, hac);
                if (rs < 0) return 0;
                int sz = rs & 15;
                r = rs >> 4;
                if (sz == 0) {
                    if (r < 15) {
                        j->eob_run = 1 << r;
                        if (r) {
                            if (jpeg_bits_broken(j)) return -2;
                            j->eob_run += stbi__jpeg_get_bits(j, r);
                        }
                        --j->eob_run;
                        break;
                    }
                    k += 16;
                    continue;
                }
                k += r;
                zig = stbi__jpeg_dezigzag[k++];
                if (jpeg_bits_broken(j)) return -2;
                v = (short)(stbi__extend_receive(j, sz) * (1 << shift));
            }
            *nz = v ? *nz | 1ull << zig : *nz & ~(1ull << zig);
        } while (k <= j->spec_end);
        return 1;
    }
    if (j->eob_run) { /* refinement: one bit for each coefficient already there */
        --j->eob_run;
        for (; k <= j->spec_end; ++k) {
            if (!(*nz >> stbi__jpeg_dezigzag[k] & 1)) continue;
            if (jpeg_bits_broken(j)) return -2;
            (void)stbi__jpeg_get_bit(j);
        }
        return 1;
    }
    do {
        if (jpeg_bits_broken(j)) return -2;
        int rs = stbi__jpeg_huff_decode(j, hac);
        if (rs < 0) return 0;
        int sz = rs & 15, r = rs >> 4;
        if (sz == 0) {
            if (r < 15) {
                j->eob_run = (1 << r) - 1;
                if (r) {
                    if (jpeg_bits_broken(j)) return -2;
                    j->eob_run += stbi__jpeg_get_bits(j, r);
                }
                r = 64; /* the end of the block */
            }
        } else {
            if (sz != 1) return 0;
            if (jpeg_bits_broken(j)) return -2;
            (void)stbi__jpeg_get_bit(j); /* the sign: the new coefficient is not zero */
        }
        while (k <= j->spec_end) {
            unsigned zig = stbi__jpeg_dezigzag[k++];
            if (*nz >> zig & 1) {
                if (jpeg_bits_broken(j)) return -2;
                (void)stbi__jpeg_get_bit(j);
            } else {
                if (r == 0) {
                    if (sz) *nz |= 1ull << zig; /* stb writes s: +-bit, or 0 for a run of 16 */
                    break;
                }
                --r;
            }
        }
    } while (k <= j->spec_end);
    return 1;
}

/* One scan's entropy-coded data, walked as stbi__parse_entropy_coded_data walks it (block order,
 * restart intervals); 0, -1, -2 or 1 as above. nz: per component, the non-zero coefficients of each
 * of its coeff_w x coeff_h blocks (progressive AC scans). */
static int jpeg_check_scan(stbi__jpeg *z, uint64_t *const *nz) {
    stbi__jpeg_reset(z);
    int one = z->scan_n == 1, n0 = z->order[0];
    int w = one ? (z->img_comp[n0].x + 7) >> 3 : z->img_mcu_x;
    int h = one ? (z->img_comp[n0].y + 7) >> 3 : z->img_mcu_y;
    for (int y = 0; y < h; y++) {
        for (int x = 0; x < w; x++) {
            for (int k = 0; k < z->scan_n; k++) {
                int n = z->order[k];
                int blocks = one ? 1 : z->img_comp[n].h * z->img_comp[n].v;
                for (int i = 0; i < blocks; i++) {
                    int ha = z->img_comp[n].ha, r;
                    if (z->progressive && z->spec_start != 0 && one)
                        r = jpeg_check_block_prog_ac(z, z->huff_ac + ha, z->fast_ac[ha],
                                                     &nz[n][(size_t)x + (size_t)y * (size_t)z->img_comp[n].coeff_w]);
                    else if (z->progressive)
                        r = jpeg_check_block_prog_dc(z, z->huff_dc + z->img_comp[n].hd, n);
                    else
                        r = jpeg_check_block(z, z->huff_dc + z->img_comp[n].hd, z->huff_ac + ha, z->fast_ac[ha], n,
                                             z->dequant[z->img_comp[n].tq][0]);
                    if (r <= 0) return r;
                }
            }
            if (--z->todo <= 0) {
                if (jpeg_bits_broken(z)) return -2;
                if (z->code_bits < 24) stbi__grow_buffer_unsafe(z);
                if (!STBI__RESTART(z->marker)) return 1;
                stbi__jpeg_reset(z);
            }
        }
    }
    return 1;
}

/* Why stb_image must not decode the JPEG: a scan would drive a DC coefficient out of range (see
 * jpeg_dc_out_of_range) or stb's count of bits to where it breaks (jpeg_bits_broken), found by a
 * dry run of stb's own marker parser and bit reader over the entropy-coded data before stb
 * decodes it; NULL otherwise, and where stb fails by itself (it then reports why). */
static const char *jpeg_entropy_problem(const uint8_t *d, size_t n) {
    stbi__context s;
    stbi__start_mem(&s, d, (int)n);
    stbi__jpeg *z = io_malloc(sizeof *z);
    if (!z) return "out of memory";
    memset(z, 0, sizeof *z);
    z->s = &s;
    const char *why = NULL;
    uint64_t *nz[4] = {NULL, NULL, NULL, NULL}; /* progressive: each component's non-zero AC coefficients */
    if (!stbi__decode_jpeg_header(z, STBI__SCAN_header)) goto done;
    /* the MCU geometry stbi__process_frame_header computes only when it allocates */
    int hmax = 1, vmax = 1;
    for (int i = 0; i < s.img_n; i++) {
        if (z->img_comp[i].h > hmax) hmax = z->img_comp[i].h;
        if (z->img_comp[i].v > vmax) vmax = z->img_comp[i].v;
    }
    for (int i = 0; i < s.img_n; i++)
        if (hmax % z->img_comp[i].h || vmax % z->img_comp[i].v) goto done; /* stb refuses it */
    z->img_mcu_x = (int)((s.img_x + (unsigned)hmax * 8 - 1) / ((unsigned)hmax * 8));
    z->img_mcu_y = (int)((s.img_y + (unsigned)vmax * 8 - 1) / ((unsigned)vmax * 8));
    for (int i = 0; i < s.img_n; i++) {
        z->img_comp[i].x = (int)((s.img_x * (unsigned)z->img_comp[i].h + (unsigned)hmax - 1) / (unsigned)hmax);
        z->img_comp[i].y = (int)((s.img_y * (unsigned)z->img_comp[i].v + (unsigned)vmax - 1) / (unsigned)vmax);
        z->img_comp[i].coeff_w = z->img_mcu_x * z->img_comp[i].h;
        z->img_comp[i].coeff_h = z->img_mcu_y * z->img_comp[i].v;
        if (z->progressive && i < 4 &&
            !(nz[i] = io_calloc((size_t)z->img_comp[i].coeff_w * (size_t)z->img_comp[i].coeff_h, sizeof(uint64_t)))) {
            why = "out of memory";
            goto done;
        }
    }
    /* stbi__decode_jpeg_image's marker loop */
    for (int m = stbi__get_marker(z); !stbi__EOI(m); m = stbi__get_marker(z)) {
        if (stbi__SOS(m)) {
            if (!stbi__process_scan_header(z)) break;
            int r = jpeg_check_scan(z, nz);
            if (r == -1) why = "corrupt JPEG (a DC coefficient out of range)";
            if (r == -2) why = "corrupt JPEG (entropy-coded data cut inside a code by a marker)";
            if (r <= 0) break;
            if (z->marker == STBI__MARKER_none) {
                while (!stbi__at_eof(z->s)) {
                    if (stbi__get8(z->s) == 255) {
                        z->marker = stbi__get8(z->s);
                        break;
                    }
                }
            }
        } else if (stbi__DNL(m)) {
            int ld = stbi__get16be(z->s);
            if (ld != 4 || (stbi__uint32)stbi__get16be(z->s) != s.img_y) break; /* stb refuses it */
        } else if (!stbi__process_marker(z, m)) {
            break;
        }
    }
done:
    for (int i = 0; i < 4; i++) free(nz[i]);
    free(z);
    return why;
}

/* True when every PNG chunk's declared length fits in the bytes that follow it (stb_image grows its
 * IDAT buffer to the declared length, up to 1 GiB, before reading: a 200-byte file asked for
 * 1.6 GB) and the first IDAT is not empty. */
static bool png_chunks_ok(const uint8_t *d, size_t n) {
    size_t i = 8; /* after the signature */
    bool data = false;
    while (i + 12 <= n) {
        uint32_t len = (uint32_t)d[i] << 24 | (uint32_t)d[i + 1] << 16 | (uint32_t)d[i + 2] << 8 | d[i + 3];
        if (len > n - i - 12) return false;
        if (memcmp(d + i + 4, "IEND", 4) == 0) return true;
        if (memcmp(d + i + 4, "IDAT", 4) == 0) {
            if (len == 0 && !data) return false; /* stb_image then reads into a NULL buffer (UB) */
            data = true;
        }
        i += 12 + (size_t)len;
    }
    return i == n; /* no IEND: stb decides on what is there */
}

/* Decodes an image stb_image reads (PNG, JPEG, TGA, BMP) held in memory into 8-bit RGB (io_malloc'd), after
 * the checks above and the pixel cap, whether it came from a file or from inside a glTF; NULL with
 * the reason in *why (which may point into ctx->why) otherwise. *alpha: the file's alpha channel
 * (io_malloc'd), NULL when it has none or it is 255 everywhere. */
static uint8_t *stb_decode(io_ctx *ctx, const void *data, size_t size, int32_t *w, int32_t *h, uint8_t **alpha,
                           const char **why) {
    *alpha = NULL;
    if (size > INT32_MAX) {
        *why = "too large";
        return NULL;
    }
    int iw = 0, ih = 0, comp;
    const stbi_uc *bytes = data;
    bool jpeg = size >= 2 && bytes[0] == 0xFF; /* what stb_image's JPEG test accepts */
    bool png = size >= 8 && memcmp(bytes, "\x89PNG\r\n\x1a\n", 8) == 0;
    const char *bad = NULL;
    stbi_uc *px = NULL;
    if (jpeg && !jpeg_tables_ok(bytes, size)) { /* before stb reads the header too */
        *why = "corrupt JPEG (a Huffman table of more than 256 codes, or a scan without its table)";
    } else if (png && !png_chunks_ok(bytes, size)) {
        *why = "corrupt or truncated PNG (a chunk longer than the file, or an empty first IDAT)";
    } else if (!stbi_info_from_memory(bytes, (int)size, &iw, &ih, &comp)) {
        *why = stbi_failure_reason();
    } else if ((uint64_t)iw * (uint64_t)ih > ctx->limits.max_texture_pixels) {
        snprintf(ctx->why, sizeof ctx->why, "%dx%d is more than %llu pixels; RP_MAX_TEXTURE_PIXELS raises the limit",
                 iw, ih, (unsigned long long)ctx->limits.max_texture_pixels);
        *why = ctx->why;
    } else if (jpeg && (bad = jpeg_entropy_problem(bytes, size)) != NULL) {
        *why = bad;
    } else {
        /* grey-alpha and RGBA files (comp 2, 4) keep their alpha channel */
        px = stbi_load_from_memory(bytes, (int)size, &iw, &ih, &comp, comp == 2 || comp == 4 ? 4 : 3);
        if (!px) *why = stbi_failure_reason();
    }
    if (!px) return NULL;
    size_t n = (size_t)iw * (size_t)ih, bpp = comp == 2 || comp == 4 ? 4 : 3;
    uint8_t *rgb = io_malloc(n * 3), *a = NULL;
    bool opaque = true;
    for (size_t i = 0; bpp == 4 && i < n && opaque; i++) opaque = px[4 * i + 3] == 255;
    if (!opaque) a = io_malloc(n);
    if (rgb && (opaque || a)) { /* stb's buffer goes back to stb's allocator */
        if (bpp == 3) memcpy(rgb, px, n * 3);
        for (size_t i = 0; bpp == 4 && i < n; i++) {
            memcpy(rgb + 3 * i, px + 4 * i, 3);
            if (a) a[i] = px[4 * i + 3];
        }
    } else {
        free(rgb);
        free(a);
        rgb = a = NULL;
        *why = "out of memory";
    }
    stbi_image_free(px);
    *w = iw;
    *h = ih;
    *alpha = a;
    return rgb;
}

uint32_t tex_load(io_ctx *ctx, const char *path, const char *as_written, const char *file,
                  uint32_t line) {
    io_builder *b = &ctx->b;
    for (size_t i = 0; i < b->texture_n; i++)
        if (strcmp(b->texture_keys[i], path) == 0) return (uint32_t)i;

    io_buf buf;
    if (!vfs_read(ctx, path, &buf)) {
        char shown[IO_PATH_MAX + 256];
        vfs_display(&ctx->vfs, path, shown, sizeof shown);
        io_error(ctx, file, line, "cannot open texture '%s' (%s): %s", as_written, shown, ctx->why);
        return IO_NONE;
    }
    int32_t w = 0, h = 0;
    uint8_t *rgb = NULL, *alpha = NULL;
    const char *why = "unsupported or corrupt image";
    unsigned long failures = io_alloc_failures();
    if (buf.size >= 3 && buf.data[0] == 'P' && (buf.data[1] == '3' || buf.data[1] == '6'))
        rgb = ppm_decode(buf.data, buf.size, &w, &h, &why);
    else
        rgb = stb_decode(ctx, buf.data, buf.size, &w, &h, &alpha, &why);
    vfs_buf_free(&buf);
    if (!rgb) {
        if (io_alloc_failures() != failures) why = "out of memory"; /* stb then names another reason */
        io_error(ctx, file, line, "cannot decode texture '%s': %s", as_written, why);
        return IO_NONE;
    }
    return tex_add(ctx, path, as_written, w, h, rgb, alpha, file, line);
}

/* An image inside a glTF (data URI or buffer view) goes through the same checks as a file. */
uint32_t tex_add_encoded(io_ctx *ctx, const char *key, const char *as_written, const void *data,
                         size_t size, const char *file, uint32_t line) {
    io_builder *b = &ctx->b;
    for (size_t i = 0; i < b->texture_n; i++)
        if (strcmp(b->texture_keys[i], key) == 0) return (uint32_t)i;
    int32_t w = 0, h = 0;
    const char *why = "unsupported or corrupt image";
    unsigned long failures = io_alloc_failures();
    uint8_t *alpha = NULL, *rgb = stb_decode(ctx, data, size, &w, &h, &alpha, &why);
    if (!rgb) {
        if (io_alloc_failures() != failures) why = "out of memory";
        io_error(ctx, file, line, "cannot decode texture '%s': %s", as_written, why);
        return IO_NONE;
    }
    return tex_add(ctx, key, as_written, w, h, rgb, alpha, file, line);
}

uint32_t tex_add(io_ctx *ctx, const char *path, const char *as_written, int32_t w, int32_t h, uint8_t *rgb,
                 uint8_t *alpha, const char *file, uint32_t line) {
    io_builder *b = &ctx->b;
    for (size_t i = 0; i < b->texture_n; i++)
        if (strcmp(b->texture_keys[i], path) == 0) {
            free(rgb);
            free(alpha);
            return (uint32_t)i;
        }
    char *key = io_strdup(path);
    /* texture_keys and texture_claimed grow with textures: same capacity. */
    char **keys = key && b->texture_n < INT32_MAX &&
                          io_reserve((void **)&b->textures, &b->texture_cap, b->texture_n + 1, sizeof(rp_texture_data))
                      ? io_realloc(b->texture_keys, b->texture_cap * sizeof(char *))
                      : NULL;
    if (keys) b->texture_keys = keys;
    bool *claimed = keys ? io_realloc(b->texture_claimed, b->texture_cap * sizeof(bool)) : NULL;
    if (claimed) b->texture_claimed = claimed;
    if (!claimed) {
        free(key);
        free(rgb);
        free(alpha);
        io_error(ctx, file, line, "out of memory");
        return IO_NONE;
    }
    rp_texture_data *t = &b->textures[b->texture_n];
    memset(t, 0, sizeof *t);
    snprintf(t->path, sizeof t->path, "%s", as_written);
    t->width = w;
    t->height = h;
    t->rgb = rgb;
    t->alpha = alpha;
    b->texture_keys[b->texture_n] = key;
    b->texture_claimed[b->texture_n] = false;
    return (uint32_t)b->texture_n++;
}

static bool sampler_is(const rp_texture_data *t, const tex_sampler *s) {
    return t->wrap_u == s->wrap_u && t->wrap_v == s->wrap_v && t->filter == s->filter;
}

/* The first use of an image claims its entry for its sampler (set in place: the texels are not
 * touched); a use under another sampler, or with a remap, gets an entry of its own, keyed
 * "key#sampler ...", with a copy of the texels, so no two entries share memory and an image read
 * one way only is held once. */
uint32_t tex_sampled(io_ctx *ctx, uint32_t image, const tex_sampler *s, const char *file, uint32_t line) {
    io_builder *b = &ctx->b;
    rp_texture_data *t = &b->textures[image];
    bool remap = s->mm_base != 0.0f || s->mm_gain != 1.0f;
    if (!remap && !b->texture_claimed[image]) {
        t->wrap_u = s->wrap_u, t->wrap_v = s->wrap_v, t->filter = s->filter;
        b->texture_claimed[image] = true;
    }
    if (!remap && sampler_is(t, s)) return image;
    char key[IO_PATH_MAX + 96];
    snprintf(key, sizeof key, "%s#sampler %d %d %d mm %.9g %.9g", b->texture_keys[image], (int)s->wrap_u,
             (int)s->wrap_v, (int)s->filter, (double)s->mm_base, (double)s->mm_gain);
    for (size_t i = 0; i < b->texture_n; i++)
        if (strcmp(b->texture_keys[i], key) == 0) return (uint32_t)i;
    size_t n = (size_t)t->width * (size_t)t->height;
    uint8_t *rgb = io_malloc(3 * n), *alpha = t->alpha ? io_malloc(n) : NULL;
    if (!rgb || (t->alpha && !alpha)) {
        free(rgb);
        io_error(ctx, file, line, "out of memory");
        return IO_NONE;
    }
    memcpy(rgb, t->rgb, 3 * n);
    if (alpha) memcpy(alpha, t->alpha, n);
    if (remap) {
        /* value = base + gain * texel, per stored value (the table serves every byte) */
        uint8_t map[256];
        for (int v = 0; v < 256; v++) {
            float x = s->mm_base + s->mm_gain * ((float)v * (1.0f / 255.0f));
            map[v] = (uint8_t)lrintf(255.0f * fminf(fmaxf(x, 0.0f), 1.0f));
        }
        for (size_t i = 0; i < 3 * n; i++) rgb[i] = map[rgb[i]];
        for (size_t i = 0; alpha && i < n; i++) alpha[i] = map[alpha[i]];
    }
    char shown[sizeof t->path + 48]; /* info shows the remap as it shows a bump map's normals */
    if (remap) snprintf(shown, sizeof shown, "%s (-mm %g %g)", t->path, (double)s->mm_base, (double)s->mm_gain);
    else snprintf(shown, sizeof shown, "%s", t->path);
    uint32_t k = tex_add(ctx, key, shown, t->width, t->height, rgb, alpha, file, line);
    if (k != IO_NONE) { /* t may have moved */
        rp_texture_data *v = &b->textures[k];
        v->wrap_u = s->wrap_u, v->wrap_v = s->wrap_v, v->filter = s->filter;
        b->texture_claimed[k] = true;
    }
    return k;
}

/* ---- bump maps -------------------------------------------------------------------------------- */

/* Texel index i (one step outside [0, n) at most) as the renderer's lookups wrap it: repeat
 * around, clamp and mirror to the edge texel (mirroring repeats the edge texel across it). */
static int32_t bump_wrap(int32_t i, int32_t n, rp_texture_wrap wrap) {
    if (wrap == RP_TEXTURE_CLAMP || wrap == RP_TEXTURE_MIRROR) return i < 0 ? 0 : i >= n ? n - 1 : i;
    return (i % n + n) % n;
}

/* The height of texel (x, y) of a bump map, in [0, 1]: the mean of its channels (grey images have
 * three equal ones), across the edges as the renderer's lookups wrap. */
static float bump_height(const rp_texture_data *t, int32_t x, int32_t y) {
    x = bump_wrap(x, t->width, t->wrap_u);
    y = bump_wrap(y, t->height, t->wrap_v);
    const uint8_t *p = t->rgb + ((size_t)y * (size_t)t->width + (size_t)x) * 3;
    return (float)(p[0] + p[1] + p[2]) * (1.0f / 765.0f);
}

int tex_bump_kind(io_ctx *ctx, uint32_t height) {
    const rp_texture_data *t = &ctx->b.textures[height];
    size_t n = (size_t)t->width * (size_t)t->height, coloured = 0;
    double blue = 0.0;
    bool flat = true;
    for (size_t i = 0; i < n; i++) {
        const uint8_t *p = t->rgb + 3 * i;
        int lo = p[0] < p[1] ? p[0] : p[1], hi = p[0] < p[1] ? p[1] : p[0];
        if (p[2] < lo) lo = p[2];
        if (p[2] > hi) hi = p[2];
        coloured += hi - lo > 24;
        blue += p[2];
        flat &= p[0] + p[1] + p[2] == t->rgb[0] + t->rgb[1] + t->rgb[2];
    }
    /* a tangent-space normal map is bluish (z up) and far from grey over most of it */
    if (2 * coloured > n && blue > 0.6 * 255.0 * (double)n) return TEX_BUMP_NORMALS;
    return flat ? TEX_BUMP_FLAT : TEX_BUMP_HEIGHT;
}

uint32_t tex_bump_to_normal(io_ctx *ctx, uint32_t height, float scale, const char *file, uint32_t line) {
    io_builder *b = &ctx->b;
    char key[IO_PATH_MAX + 64];
    snprintf(key, sizeof key, "%s#bump %.9g", b->texture_keys[height], (double)scale); /* the key names its sampler */
    for (size_t i = 0; i < b->texture_n; i++)
        if (strcmp(b->texture_keys[i], key) == 0) return (uint32_t)i;
    const rp_texture_data *t = &b->textures[height];
    if (!isfinite(scale * IO_BUMP_STRENGTH)) { /* -bm 3e38: the normals would be NaN */
        io_error(ctx, file, line, "bump map %s: -bm %g is too large", t->path, (double)scale);
        return IO_NONE;
    }
    size_t n = (size_t)t->width * (size_t)t->height;
    uint8_t *rgb = io_malloc(3 * n);
    if (!rgb) {
        io_error(ctx, file, line, "out of memory");
        return IO_NONE;
    }
    /* Central differences in texel units; +u is +x, +v is up (the image's rows run down). The
     * normal of the height field s h(u, v) is (-s dh/du, -s dh/dv, 1). */
    float k = scale * IO_BUMP_STRENGTH;
    for (int32_t y = 0; y < t->height; y++)
        for (int32_t x = 0; x < t->width; x++) {
            float du = 0.5f * (bump_height(t, x + 1, y) - bump_height(t, x - 1, y));
            float dv = 0.5f * (bump_height(t, x, y - 1) - bump_height(t, x, y + 1));
            float nx = -k * du, ny = -k * dv, nz = 1.0f;
            float inv = 1.0f / sqrtf(nx * nx + ny * ny + nz * nz);
            const float c[3] = {nx * inv, ny * inv, nz * inv};
            uint8_t *p = rgb + ((size_t)y * (size_t)t->width + (size_t)x) * 3;
            for (int j = 0; j < 3; j++) p[j] = (uint8_t)lrintf((c[j] * 0.5f + 0.5f) * 255.0f);
        }
    char shown[sizeof t->path + 16];
    snprintf(shown, sizeof shown, "%s (bump normals)", t->path);
    tex_sampler sampler = {t->wrap_u, t->wrap_v, t->filter, 0.0f, 1.0f};
    uint32_t normals = tex_add(ctx, key, shown, t->width, t->height, rgb, NULL, file, line);
    if (normals != IO_NONE) tex_sampled(ctx, normals, &sampler, file, line); /* read as its heights are */
    return normals;
}
