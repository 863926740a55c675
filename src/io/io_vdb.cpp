// OpenVDB files (Debian's libopenvdb-dev, OpenVDB 10): the one C++ file of raypack. It opens the
// file, picks a float grid and copies its active voxels (and active tiles, voxel by voxel) into
// raypack's C brick grid through io_volume.h; every exception stops at this file's boundary and
// becomes a message naming the reason. The grid's transform must be linear (an affine map from
// index to world); frustum transforms are refused.
#include <cerrno>
#include <cstdint>
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

// Walks the parts of a .vdb file that declare lengths OpenVDB allocates before it reads them: the
// header, the file's metadata, each grid's descriptor and each grid's metadata. OpenVDB 10 makes a
// string (zero-filled) of whatever length a file declares, up to 4 GiB, before it finds the file too
// short: a corrupt 10 kB file took 25 s and 3 GB to be refused. Here every length and position must
// lie inside the file. The grids' trees are left to OpenVDB (their sizes follow from node masks).
class vdb_walk {
  public:
    vdb_walk(std::istream &is, uint64_t size) : is_(is), size_(size) {}

    bool check(std::string *fail) {
        is_.seekg(8); // past the magic number, which the caller checked
        uint32_t version = 0, major = 0, minor = 0;
        if (!u32(&version, "the file format version")) return stop(fail);
        if (version < 222) return true; // older layouts: left to OpenVDB (no grid compression flags)
        if (!u32(&major, "the library version") || !u32(&minor, "the library version")) return stop(fail);
        char offsets = 0;
        if (!bytes(&offsets, 1, "the grid offsets flag") || !skip(36, "the file's UUID")) return stop(fail);
        if (!meta("the file's metadata")) return stop(fail);
        uint32_t grids = 0;
        if (!u32(&grids, "the grid count")) return stop(fail);
        for (uint32_t g = 0; g < grids; g++) {
            std::string what = "grid " + std::to_string(g + 1) + "'s descriptor";
            int64_t pos[3];
            if (!string(what + " (its name)") || !string(what + " (its type)") ||
                (version >= 223 && !string(what + " (its instance parent)")))
                return stop(fail);
            for (int k = 0; k < 3; k++)
                if (!bytes(&pos[k], 8, what)) return stop(fail);
            if (offsets && !(pos[0] >= 0 && pos[0] <= pos[1] && pos[1] <= pos[2] && (uint64_t)pos[2] <= size_)) {
                why_ = what + " places the grid at bytes " + std::to_string(pos[0]) + " to " + std::to_string(pos[2]) +
                       ", outside the file (" + std::to_string(size_) + " bytes)";
                return stop(fail);
            }
            if (offsets) is_.seekg(pos[0]);
            uint32_t compression = 0;
            if (!u32(&compression, "grid " + std::to_string(g + 1) + "'s compression flags") ||
                !meta("grid " + std::to_string(g + 1) + "'s metadata"))
                return stop(fail);
            if (!offsets) return true; // the next descriptor lies past this grid's tree
            is_.seekg(pos[2]);
        }
        return true;
    }

  private:
    std::istream &is_;
    uint64_t size_;
    std::string why_;

    bool stop(std::string *fail) {
        *fail = "truncated or corrupt OpenVDB file: " + why_;
        return false;
    }
    uint64_t left() {
        std::streamoff at = is_.tellg();
        return at < 0 || (uint64_t)at > size_ ? 0 : size_ - (uint64_t)at;
    }
    bool bytes(void *dst, uint64_t n, const std::string &what) {
        if (n > left()) {
            why_ = what + " runs past the file's end";
            return false;
        }
        is_.read(static_cast<char *>(dst), (std::streamsize)n);
        return true;
    }
    bool u32(uint32_t *dst, const std::string &what) { return bytes(dst, 4, what); }
    bool skip(uint64_t n, const std::string &what) {
        if (n > left()) {
            why_ = what + " runs past the file's end";
            return false;
        }
        is_.seekg((std::streamoff)n, std::ios::cur);
        return true;
    }
    // A length-prefixed run of bytes (a string, a metadata value).
    bool sized(const std::string &what) {
        std::streamoff at = is_.tellg();
        uint32_t n = 0;
        if (!u32(&n, what)) return false;
        if (n > left()) {
            why_ = what + " declares " + std::to_string(n) + " bytes at byte " + std::to_string(at) + ", past the file's end (" +
                   std::to_string(size_) + " bytes)";
            return false;
        }
        is_.seekg((std::streamoff)n, std::ios::cur);
        return true;
    }
    bool string(const std::string &what) { return sized(what); }
    bool meta(const std::string &what) {
        uint32_t count = 0;
        if (!u32(&count, what + " (its entry count)")) return false;
        for (uint32_t i = 0; i < count; i++) {
            std::string entry = what + ", entry " + std::to_string(i + 1);
            if (!string(entry + " (its name)") || !string(entry + " (its type)") || !sized(entry + " (its value)"))
                return false;
        }
        return true;
    }
};

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
    is.seekg(0, std::ios::end);
    std::streamoff size = is.tellg();
    if (size < 0) {
        *fail = "cannot find the file's size";
        return false;
    }
    if (!vdb_walk(is, (uint64_t)size).check(fail)) return false;
    is.clear();
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
