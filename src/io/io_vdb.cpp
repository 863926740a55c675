// OpenVDB files (Debian's libopenvdb-dev, OpenVDB 10): the one C++ file of raypack. It opens the
// file, picks a float grid and copies its active voxels (and active tiles, voxel by voxel) into
// raypack's C brick grid through io_volume.h; every exception stops at this file's boundary and
// becomes a message naming the reason. The grid's transform must be linear (an affine map from
// index to world); frustum transforms are refused.
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <exception>
#include <fstream>
#include <ios>
#include <new>
#include <string>

// raypack_io is built with -fvisibility=hidden, but OpenVDB's templates must keep default
// visibility: hidden copies of their static members (the grid type registry's) in this object
// make openvdb::initialize() crash inside libopenvdb. Only this file's own functions stay hidden.
#pragma GCC visibility push(default)
#include <openvdb/openvdb.h>
#include <openvdb/io/Stream.h>
#include <oneapi/tbb/task_arena.h>
#pragma GCC visibility pop

#include "io/io_volume.h"

namespace {

void set_why(char *why, size_t why_size, const std::string &msg) {
    if (why && why_size) std::snprintf(why, why_size, "%s", msg.c_str());
}

// The float grid to read among the file's grids, or null with the reason in *fail.
openvdb::FloatGrid::Ptr pick_grid(const openvdb::GridPtrVec &grids, const char *wanted, std::string *fail) {
    std::string listing;
    openvdb::FloatGrid::Ptr first, density;
    for (const openvdb::GridBase::Ptr &g : grids) {
        std::string name = g->getName();
        listing += (listing.empty() ? "" : ", ") + (name.empty() ? std::string("(unnamed)") : name) + " (" +
                   g->valueType() + ")";
        openvdb::FloatGrid::Ptr f = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
        if (!f) continue;
        if (wanted && *wanted && name == wanted) return f;
        if (!first) first = f;
        if (!density && name == "density") density = f;
    }
    if (listing.empty()) listing = "none";
    if (wanted && *wanted) {
        *fail = std::string("no float grid named '") + wanted + "' (grids: " + listing + ")";
        return nullptr;
    }
    if (density) return density;
    if (!first) *fail = "no float grid (grids: " + listing + ")";
    return first;
}

bool read_grid(const char *path, const char *wanted, rp_volume_data *v, std::string *fail) {
    openvdb::initialize(); // idempotent and thread-safe: registers the grid types
    std::ifstream is(path, std::ios::binary);
    if (!is) {
        *fail = std::string("cannot open: ") + std::strerror(errno);
        return false;
    }
    unsigned char magic[8] = {0};
    is.read(reinterpret_cast<char *>(magic), sizeof magic);
    // OpenVDB's magic number, 0x56444220 ("VDB "), as a little-endian int64
    static const unsigned char vdb_magic[8] = {0x20, 0x42, 0x44, 0x56, 0, 0, 0, 0};
    if (is.gcount() != 8 || std::memcmp(magic, vdb_magic, 8) != 0) {
        *fail = "not an OpenVDB file (no VDB magic number at its start)";
        return false;
    }
    is.seekg(0);
    // A short read throws (std::ios_base::failure) instead of leaving OpenVDB with a half-read
    // grid: io::File reads a truncated file without complaint.
    is.exceptions(std::ios::failbit | std::ios::badbit);
    openvdb::GridPtrVecPtr grids;
    try {
        openvdb::io::Stream stream(is, false); // every grid read now
        grids = stream.getGrids();
    } catch (const std::ios_base::failure &) {
        *fail = "truncated or corrupt OpenVDB file (read past its end)";
        return false;
    }
    if (!grids) {
        *fail = "no grids in the file";
        return false;
    }
    openvdb::FloatGrid::Ptr grid = pick_grid(*grids, wanted, fail);
    if (!grid) return false;
    std::string name = grid->getName();
    const openvdb::math::Transform &xf = grid->transform();
    if (!xf.isLinear()) {
        *fail = "grid '" + name + "' has a non-linear (frustum) transform";
        return false;
    }
    // OpenVDB's matrices act on row vectors: world = (i, j, k, 1) M, translation in row 3.
    openvdb::Mat4d m = xf.baseMap()->getAffineMap()->getMat4();
    float xfm[12];
    for (int a = 0; a < 3; a++) {
        for (int r = 0; r < 3; r++) xfm[4 * a + r] = static_cast<float>(m[r][a]);
        xfm[4 * a + 3] = static_cast<float>(m[3][a]);
    }
    std::snprintf(v->grid_name, sizeof v->grid_name, "%s", name.c_str());
    openvdb::Index64 active = grid->activeVoxelCount();
    if (active > (openvdb::Index64(1) << 30)) { // 4 GiB of densities, at least
        *fail = "grid '" + name + "' has too many active voxels (" + std::to_string(active) + ")";
        return false;
    }
    openvdb::CoordBBox box = grid->evalActiveVoxelBoundingBox();
    if (box.empty()) return true; // no active voxel: the caller says so
    int32_t lo[3] = {box.min().x(), box.min().y(), box.min().z()};
    int32_t hi[3] = {box.max().x(), box.max().y(), box.max().z()};
    if (!io_volume_begin(v, lo, hi, xfm)) {
        char msg[160];
        std::snprintf(msg, sizeof msg, "' is too large (active voxels from %d,%d,%d to %d,%d,%d)", lo[0], lo[1], lo[2],
                      hi[0], hi[1], hi[2]);
        *fail = "grid '" + name + msg;
        return false;
    }
    for (openvdb::FloatGrid::ValueOnCIter it = grid->cbeginValueOn(); it; ++it) {
        float value = *it;
        if (it.isVoxelValue()) {
            openvdb::Coord c = it.getCoord();
            if (!io_volume_set(v, c.x(), c.y(), c.z(), value)) throw std::bad_alloc();
            continue;
        }
        openvdb::CoordBBox tile; // an active tile: every voxel it covers
        it.getBoundingBox(tile);
        for (int32_t k = tile.min().z(); k <= tile.max().z(); k++)
            for (int32_t j = tile.min().y(); j <= tile.max().y(); j++)
                for (int32_t i = tile.min().x(); i <= tile.max().x(); i++)
                    if (!io_volume_set(v, i, j, k, value)) throw std::bad_alloc();
    }
    if (!io_volume_finish(v)) throw std::bad_alloc();
    return true;
}

} // namespace

extern "C" bool io_vdb_read(const char *path, const char *grid, rp_volume_data *v, char *why, size_t why_size) {
    std::string fail;
    try {
        // OpenVDB counts, bounds and frees trees with TBB's parallel_for. A one-slot arena keeps that work on
        // this thread: it is short, the renderer's threads need not compete with TBB's pool, and ThreadSanitizer
        // (which cannot see libtbb's uninstrumented synchronisation) reports no false races.
        tbb::task_arena one(1);
        if (one.execute([&] { return read_grid(path, grid, v, &fail); })) return true;
    } catch (const openvdb::Exception &e) {
        fail = e.what(); // "IoError: ..." and the like
    } catch (const std::bad_alloc &) {
        fail = "out of memory";
    } catch (const std::exception &e) {
        fail = std::string("cannot read the OpenVDB file: ") + e.what();
    } catch (...) {
        fail = "cannot read the OpenVDB file (unknown exception)";
    }
    try {
        set_why(why, why_size, fail.empty() ? std::string("cannot read the OpenVDB file") : fail);
    } catch (...) {
        set_why(why, why_size, "out of memory");
    }
    return false;
}
