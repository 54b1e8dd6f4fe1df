// grin_vdb.cpp: grin's C++17 shim over OpenVDB 10 (see grin_vdb.h for the contract).
// Every extern "C" entry point catches every exception and turns it into a status code
// plus message: nothing unwinds into Rust.

#include "grin_vdb.h"

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>
#include <openvdb/io/Stream.h>
#include <openvdb/tools/Dense.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <ios>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <type_traits>
#include <vector>

namespace {

struct MetaEntry {
    std::string key;
    std::string type_name;
    int32_t kind = GRIN_VDB_META_OTHER;
    std::string text;
    double number = 0.0;
};

struct GridEntry {
    openvdb::GridBase::Ptr grid;
    std::string name, value_type, grid_class, map_type;
    GrinVdbGridInfo info{};
    std::vector<MetaEntry> meta;
};

void set_err(char* err, size_t err_len, const std::string& msg) {
    if (err == nullptr || err_len == 0) return;
    size_t n = msg.size() < err_len - 1 ? msg.size() : err_len - 1;
    std::memcpy(err, msg.data(), n);
    err[n] = '\0';
}

// Run `body`, mapping exceptions to status codes.
template <typename F>
int guarded(char* err, size_t err_len, F&& body) {
    try {
        return body();
    } catch (const openvdb::IoError& e) {
        set_err(err, err_len, e.what());
        return GRIN_VDB_ERR_IO;
    } catch (const openvdb::Exception& e) {
        set_err(err, err_len, e.what());
        return GRIN_VDB_ERR_IO;
    } catch (const std::ios_base::failure&) {
        set_err(err, err_len, "the file is truncated or corrupt (unexpected end of data)");
        return GRIN_VDB_ERR_IO;
    } catch (const std::bad_alloc&) {
        set_err(err, err_len, "out of memory while reading the file");
        return GRIN_VDB_ERR_MEMORY;
    } catch (const std::exception& e) {
        set_err(err, err_len, e.what());
        return GRIN_VDB_ERR_OTHER;
    } catch (...) {
        set_err(err, err_len, "unknown C++ exception");
        return GRIN_VDB_ERR_OTHER;
    }
}

void init_once() { openvdb::initialize(); }

std::vector<MetaEntry> collect_meta(const openvdb::MetaMap& map) {
    std::vector<MetaEntry> out;
    for (auto it = map.beginMeta(); it != map.endMeta(); ++it) {
        MetaEntry m;
        m.key = it->first;
        if (!it->second) continue;
        m.type_name = it->second->typeName();
        const openvdb::Metadata& md = *it->second;
        if (auto s = dynamic_cast<const openvdb::StringMetadata*>(&md)) {
            m.kind = GRIN_VDB_META_STRING;
            m.text = s->value();
        } else if (auto f = dynamic_cast<const openvdb::FloatMetadata*>(&md)) {
            m.kind = GRIN_VDB_META_NUMBER;
            m.number = f->value();
        } else if (auto d = dynamic_cast<const openvdb::DoubleMetadata*>(&md)) {
            m.kind = GRIN_VDB_META_NUMBER;
            m.number = d->value();
        } else if (auto i32 = dynamic_cast<const openvdb::Int32Metadata*>(&md)) {
            m.kind = GRIN_VDB_META_NUMBER;
            m.number = i32->value();
        } else if (auto i64 = dynamic_cast<const openvdb::Int64Metadata*>(&md)) {
            m.kind = GRIN_VDB_META_NUMBER;
            m.number = static_cast<double>(i64->value());
        } else if (auto b = dynamic_cast<const openvdb::BoolMetadata*>(&md)) {
            m.kind = GRIN_VDB_META_NUMBER;
            m.number = b->value() ? 1.0 : 0.0;
        } else {
            m.kind = GRIN_VDB_META_OTHER;
            m.text = md.str();
        }
        if (m.kind == GRIN_VDB_META_NUMBER) m.text = md.str();
        out.push_back(std::move(m));
    }
    return out;
}

template <typename GridT>
void scalar_stats(const GridT& grid, GrinVdbGridInfo& info) {
    double lo = std::numeric_limits<double>::infinity();
    double hi = -lo;
    uint64_t bad = 0;
    const double background = static_cast<double>(grid.background());
    // Where the values differ from the background: a box over the active voxels and
    // tiles (a tile counts whole), found without a dense copy.
    openvdb::CoordBBox data;
    uint64_t data_count = 0;
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        const double v = static_cast<double>(*it);
        if (!(v == background)) {
            openvdb::CoordBBox b;
            it.getBoundingBox(b);
            data.expand(b);
            data_count += it.getVoxelCount();
        }
        if (!std::isfinite(v)) {
            bad += it.getVoxelCount();
            continue;
        }
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
    info.non_finite_count = bad;
    info.value_min = lo;
    info.value_max = hi;
    info.background = background;
    info.data_voxel_count = data_count;
    for (int i = 0; i < 3; ++i) {
        info.data_min[i] = data_count == 0 ? 0 : data.min()[i];
        info.data_max[i] = data_count == 0 ? -1 : data.max()[i];
    }
}

template <typename GridT>
void vec_stats(const GridT& grid, GrinVdbGridInfo& info) {
    double lo = std::numeric_limits<double>::infinity();
    double hi = -lo;
    uint64_t bad = 0;
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        const auto v = *it;
        const double x = v[0], y = v[1], z = v[2];
        if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
            bad += it.getVoxelCount();
            continue;
        }
        const double m = std::sqrt(x * x + y * y + z * z);
        lo = std::min(lo, m);
        hi = std::max(hi, m);
    }
    info.non_finite_count = bad;
    info.value_min = lo;
    info.value_max = hi;
    info.background = static_cast<double>(grid.background().length());
}

void fill_info(GridEntry& e) {
    const openvdb::GridBase& g = *e.grid;
    GrinVdbGridInfo& info = e.info;
    e.name = g.getName();
    e.value_type = g.valueType();
    e.grid_class = openvdb::GridBase::gridClassToString(g.getGridClass());
    const openvdb::math::Transform& xf = g.transform();
    e.map_type = xf.mapType();
    info.is_linear = xf.isLinear() ? 1 : 0;
    info.save_float_as_half = g.saveFloatAsHalf() ? 1 : 0;
    const openvdb::Vec3d vs = xf.voxelSize();
    for (int i = 0; i < 3; ++i) info.voxel_size[i] = vs[i];
    // OpenVDB matrices act on row vectors (p' = p * M, translation in row 3).
    const openvdb::Mat4d m = xf.baseMap()->getAffineMap()->getMat4();
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) info.world_from_index[r * 4 + c] = m(c, r);
        info.world_from_index[r * 4 + 3] = m(3, r);
    }
    const openvdb::CoordBBox bb = g.evalActiveVoxelBoundingBox();
    info.is_empty = (g.activeVoxelCount() == 0 || bb.empty()) ? 1 : 0;
    for (int i = 0; i < 3; ++i) {
        info.bbox_min[i] = info.is_empty ? 0 : bb.min()[i];
        info.bbox_max[i] = info.is_empty ? -1 : bb.max()[i];
    }
    info.active_voxel_count = g.activeVoxelCount();
    for (int i = 0; i < 3; ++i) {
        info.data_min[i] = 0;
        info.data_max[i] = -1;
    }
    info.data_voxel_count = 0;
    info.value_min = std::numeric_limits<double>::quiet_NaN();
    info.value_max = std::numeric_limits<double>::quiet_NaN();
    info.background = 0.0;
    if (auto f = openvdb::gridConstPtrCast<openvdb::FloatGrid>(e.grid)) {
        info.type_code = GRIN_VDB_TYPE_FLOAT;
        scalar_stats(*f, info);
    } else if (auto d = openvdb::gridConstPtrCast<openvdb::DoubleGrid>(e.grid)) {
        info.type_code = GRIN_VDB_TYPE_DOUBLE;
        scalar_stats(*d, info);
    } else if (auto v = openvdb::gridConstPtrCast<openvdb::Vec3SGrid>(e.grid)) {
        info.type_code = GRIN_VDB_TYPE_VEC3S;
        vec_stats(*v, info);
    } else if (auto vd = openvdb::gridConstPtrCast<openvdb::Vec3DGrid>(e.grid)) {
        info.type_code = GRIN_VDB_TYPE_VEC3D;
        vec_stats(*vd, info);
    } else {
        info.type_code = GRIN_VDB_TYPE_OTHER;
    }
    e.meta = collect_meta(g);
    info.name = e.name.c_str();
    info.value_type = e.value_type.c_str();
    info.grid_class = e.grid_class.c_str();
    info.map_type = e.map_type.c_str();
    info.meta_count = e.meta.size();
}

openvdb::CoordBBox make_box(const int32_t bmin[3], const int32_t bmax[3]) {
    return openvdb::CoordBBox(openvdb::Coord(bmin[0], bmin[1], bmin[2]),
                              openvdb::Coord(bmax[0], bmax[1], bmax[2]));
}

// Voxel count of an inclusive box, or 0 if it is empty or overflows.
uint64_t box_voxels(const int32_t bmin[3], const int32_t bmax[3]) {
    uint64_t n = 1;
    for (int i = 0; i < 3; ++i) {
        if (bmax[i] < bmin[i]) return 0;
        const uint64_t d = static_cast<uint64_t>(static_cast<int64_t>(bmax[i]) - bmin[i] + 1);
        if (n > std::numeric_limits<uint64_t>::max() / d) return 0;
        n *= d;
    }
    return n;
}

template <typename GridT, typename OutT>
void copy_box(const GridT& grid, const openvdb::CoordBBox& box, OutT* out) {
    using ValueT = typename GridT::ValueType;
    // Single-precision grids copy straight into the caller's buffer (no second copy).
    if constexpr (std::is_same_v<ValueT, float>) {
        openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ> dense(box, out);
        openvdb::tools::copyToDense(grid, dense);
        return;
    } else if constexpr (std::is_same_v<ValueT, openvdb::Vec3s>) {
        openvdb::tools::Dense<openvdb::Vec3s, openvdb::tools::LayoutXYZ> dense(
            box, reinterpret_cast<openvdb::Vec3s*>(out));
        openvdb::tools::copyToDense(grid, dense);
        return;
    }
    openvdb::tools::Dense<typename GridT::ValueType, openvdb::tools::LayoutXYZ> dense(box);
    openvdb::tools::copyToDense(grid, dense);
    const size_t n = dense.valueCount();
    const auto* src = dense.data();
    for (size_t i = 0; i < n; ++i) {
        if constexpr (std::is_same_v<OutT, float> &&
                      std::is_arithmetic_v<typename GridT::ValueType>) {
            out[i] = static_cast<float>(src[i]);
        } else {
            out[3 * i] = static_cast<float>(src[i][0]);
            out[3 * i + 1] = static_cast<float>(src[i][1]);
            out[3 * i + 2] = static_cast<float>(src[i][2]);
        }
    }
}

// The last index of a box of `dims` voxels from `origin`, in bmax; false where a side is
// empty or the box passes INT32_MAX.
bool box_max(const int32_t origin[3], const uint64_t dims[3], int32_t bmax[3]) {
    for (int i = 0; i < 3; ++i) {
        if (dims[i] == 0 || dims[i] > static_cast<uint64_t>(INT32_MAX) ||
            static_cast<int64_t>(origin[i]) + static_cast<int64_t>(dims[i]) - 1 > INT32_MAX) {
            return false;
        }
        bmax[i] = static_cast<int32_t>(origin[i] + static_cast<int64_t>(dims[i]) - 1);
    }
    return true;
}

// Copy the dense box `box` of `data` (x fastest; 3 floats a voxel for a vec3s grid) into
// `grid`, a float or vec3s grid made by the writer; the grid's voxels outside the box are
// kept (copyFromDense starts from the existing leaves). Values within `tolerance` of the
// background become inactive.
void copy_box(openvdb::GridBase& grid, const openvdb::CoordBBox& box, const float* data,
              float tolerance) {
    // copyFromDense only reads the buffer.
    if (auto* g = dynamic_cast<openvdb::FloatGrid*>(&grid)) {
        openvdb::tools::Dense<float, openvdb::tools::LayoutXYZ> dense(box,
                                                                      const_cast<float*>(data));
        openvdb::tools::copyFromDense(dense, *g, tolerance);
    } else if (auto* g = dynamic_cast<openvdb::Vec3SGrid*>(&grid)) {
        openvdb::tools::Dense<openvdb::Vec3s, openvdb::tools::LayoutXYZ> dense(
            box, reinterpret_cast<openvdb::Vec3s*>(const_cast<float*>(data)));
        openvdb::tools::copyFromDense(dense, *g, openvdb::Vec3s(tolerance));
    }
}

}  // namespace

struct GrinVdbFile {
    std::vector<GridEntry> grids;
    std::vector<MetaEntry> file_meta;
};

struct GrinVdbWriter {
    openvdb::GridPtrVec grids;
    openvdb::MetaMap file_meta;
};

extern "C" {

int grin_vdb_open(const char* path, GrinVdbFile** out, char* err, size_t err_len) {
    if (out == nullptr || path == nullptr) {
        set_err(err, err_len, "null argument");
        return GRIN_VDB_ERR_ARG;
    }
    *out = nullptr;
    return guarded(err, err_len, [&]() {
        init_once();
        auto file = std::make_unique<GrinVdbFile>();
        // io::Stream over an istream that throws on short reads: io::File ignores stream
        // errors, so a truncated file would silently read as fewer (or zero) grids.
        std::ifstream ifs(path, std::ios::in | std::ios::binary);
        if (!ifs) throw openvdb::IoError("could not open the file for reading");
        ifs.exceptions(std::ios::failbit | std::ios::badbit);
        openvdb::io::Stream stream(ifs, /*delayLoad=*/false);
        openvdb::MetaMap::Ptr meta = stream.getMetadata();
        if (meta) file->file_meta = collect_meta(*meta);
        openvdb::GridPtrVecPtr grids = stream.getGrids();
        if (grids) {
            for (auto& g : *grids) {
                if (!g) continue;
                GridEntry e;
                e.grid = g;
                fill_info(e);
                file->grids.push_back(std::move(e));
            }
        }
        // Pointers in info reference strings owned by the entries: refresh after moves.
        for (auto& e : file->grids) {
            e.info.name = e.name.c_str();
            e.info.value_type = e.value_type.c_str();
            e.info.grid_class = e.grid_class.c_str();
            e.info.map_type = e.map_type.c_str();
        }
        *out = file.release();
        return GRIN_VDB_OK;
    });
}

void grin_vdb_close(GrinVdbFile* file) {
    try {
        delete file;
    } catch (...) {
    }
}

size_t grin_vdb_grid_count(const GrinVdbFile* file) {
    return file == nullptr ? 0 : file->grids.size();
}

int grin_vdb_grid_info(const GrinVdbFile* file, size_t grid, GrinVdbGridInfo* out, char* err,
                       size_t err_len) {
    if (file == nullptr || out == nullptr || grid >= file->grids.size()) {
        set_err(err, err_len, "grid index out of range");
        return GRIN_VDB_ERR_ARG;
    }
    *out = file->grids[grid].info;
    return GRIN_VDB_OK;
}

size_t grin_vdb_file_meta_count(const GrinVdbFile* file) {
    return file == nullptr ? 0 : file->file_meta.size();
}

int grin_vdb_meta(const GrinVdbFile* file, size_t grid, size_t i, const char** key,
                  const char** type_name, int32_t* kind, const char** text, double* number,
                  char* err, size_t err_len) {
    if (file == nullptr || key == nullptr || type_name == nullptr || kind == nullptr ||
        text == nullptr || number == nullptr) {
        set_err(err, err_len, "null argument");
        return GRIN_VDB_ERR_ARG;
    }
    const std::vector<MetaEntry>* list = nullptr;
    if (grid == SIZE_MAX) {
        list = &file->file_meta;
    } else if (grid < file->grids.size()) {
        list = &file->grids[grid].meta;
    }
    if (list == nullptr || i >= list->size()) {
        set_err(err, err_len, "metadata index out of range");
        return GRIN_VDB_ERR_ARG;
    }
    const MetaEntry& m = (*list)[i];
    *key = m.key.c_str();
    *type_name = m.type_name.c_str();
    *kind = m.kind;
    *text = m.text.c_str();
    *number = m.number;
    return GRIN_VDB_OK;
}

int grin_vdb_read_scalar(const GrinVdbFile* file, size_t grid, const int32_t bmin[3],
                         const int32_t bmax[3], float* out, size_t out_len, char* err,
                         size_t err_len) {
    if (file == nullptr || bmin == nullptr || bmax == nullptr || out == nullptr ||
        grid >= file->grids.size()) {
        set_err(err, err_len, "bad argument to grin_vdb_read_scalar");
        return GRIN_VDB_ERR_ARG;
    }
    const uint64_t n = box_voxels(bmin, bmax);
    if (n == 0 || n != out_len) {
        set_err(err, err_len, "box is empty or does not match the output buffer");
        return GRIN_VDB_ERR_ARG;
    }
    return guarded(err, err_len, [&]() {
        const GridEntry& e = file->grids[grid];
        const openvdb::CoordBBox box = make_box(bmin, bmax);
        if (auto f = openvdb::gridConstPtrCast<openvdb::FloatGrid>(e.grid)) {
            copy_box(*f, box, out);
        } else if (auto d = openvdb::gridConstPtrCast<openvdb::DoubleGrid>(e.grid)) {
            copy_box(*d, box, out);
        } else {
            set_err(err, err_len, "grid `" + e.name + "` has value type " + e.value_type +
                                      ", not a scalar (float or double)");
            return static_cast<int>(GRIN_VDB_ERR_ARG);
        }
        return static_cast<int>(GRIN_VDB_OK);
    });
}

int grin_vdb_read_vec3(const GrinVdbFile* file, size_t grid, const int32_t bmin[3],
                       const int32_t bmax[3], float* out, size_t out_len, char* err,
                       size_t err_len) {
    if (file == nullptr || bmin == nullptr || bmax == nullptr || out == nullptr ||
        grid >= file->grids.size()) {
        set_err(err, err_len, "bad argument to grin_vdb_read_vec3");
        return GRIN_VDB_ERR_ARG;
    }
    const uint64_t n = box_voxels(bmin, bmax);
    if (n == 0 || n > SIZE_MAX / 3 || 3 * n != out_len) {
        set_err(err, err_len, "box is empty or does not match the output buffer");
        return GRIN_VDB_ERR_ARG;
    }
    return guarded(err, err_len, [&]() {
        const GridEntry& e = file->grids[grid];
        const openvdb::CoordBBox box = make_box(bmin, bmax);
        if (auto v = openvdb::gridConstPtrCast<openvdb::Vec3SGrid>(e.grid)) {
            copy_box(*v, box, out);
        } else if (auto vd = openvdb::gridConstPtrCast<openvdb::Vec3DGrid>(e.grid)) {
            copy_box(*vd, box, out);
        } else {
            set_err(err, err_len, "grid `" + e.name + "` has value type " + e.value_type +
                                      ", not a vec3 (vec3s or vec3d)");
            return static_cast<int>(GRIN_VDB_ERR_ARG);
        }
        return static_cast<int>(GRIN_VDB_OK);
    });
}

GrinVdbWriter* grin_vdb_writer_new(void) {
    try {
        init_once();
        return new GrinVdbWriter();
    } catch (...) {
        return nullptr;
    }
}

void grin_vdb_writer_free(GrinVdbWriter* writer) {
    try {
        delete writer;
    } catch (...) {
    }
}

int grin_vdb_writer_add_grid(GrinVdbWriter* writer, const char* name, int32_t components,
                             const int32_t origin[3], const uint64_t dims[3],
                             const float* data, size_t data_len,
                             const double world_from_index[12], float background,
                             float tolerance, int32_t save_as_half,
                             const char* const* meta_keys, const char* const* meta_values,
                             size_t n_meta, const char* const* num_keys,
                             const double* num_values, size_t n_num, char* err,
                             size_t err_len) {
    if (writer == nullptr || name == nullptr || origin == nullptr || dims == nullptr ||
        data == nullptr || world_from_index == nullptr || (components != 1 && components != 3)) {
        set_err(err, err_len, "bad argument to grin_vdb_writer_add_grid");
        return GRIN_VDB_ERR_ARG;
    }
    int32_t bmax[3];
    if (!box_max(origin, dims, bmax)) {
        set_err(err, err_len, "grid dimensions out of range");
        return GRIN_VDB_ERR_ARG;
    }
    const uint64_t n = box_voxels(origin, bmax);
    if (n == 0 || n * static_cast<uint64_t>(components) != data_len) {
        set_err(err, err_len, "data length does not match the grid dimensions");
        return GRIN_VDB_ERR_ARG;
    }
    return guarded(err, err_len, [&]() {
        openvdb::Mat4d m = openvdb::Mat4d::identity();
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) m(c, r) = world_from_index[r * 4 + c];
            m(3, r) = world_from_index[r * 4 + 3];
        }
        openvdb::math::Transform::Ptr xf = openvdb::math::Transform::createLinearTransform(m);
        openvdb::GridBase::Ptr base;
        if (components == 1) {
            auto grid = openvdb::FloatGrid::create(background);
            grid->setGridClass(openvdb::GRID_FOG_VOLUME);
            base = grid;
        } else {
            auto grid = openvdb::Vec3SGrid::create(openvdb::Vec3s(background));
            // grad n is a gradient: covariant under the transform.
            grid->setVectorType(openvdb::VEC_COVARIANT);
            base = grid;
        }
        copy_box(*base, make_box(origin, bmax), data, tolerance);
        base->setName(name);
        base->setTransform(xf);
        base->setSaveFloatAsHalf(save_as_half != 0);
        for (size_t i = 0; i < n_meta; ++i) {
            if (meta_keys[i] == nullptr || meta_values[i] == nullptr) continue;
            base->insertMeta(meta_keys[i], openvdb::StringMetadata(meta_values[i]));
        }
        for (size_t i = 0; i < n_num; ++i) {
            if (num_keys[i] == nullptr) continue;
            base->insertMeta(num_keys[i], openvdb::DoubleMetadata(num_values[i]));
        }
        writer->grids.push_back(base);
        return static_cast<int>(GRIN_VDB_OK);
    });
}

int grin_vdb_writer_add_box(GrinVdbWriter* writer, const int32_t origin[3],
                            const uint64_t dims[3], const float* data, size_t data_len,
                            float tolerance, char* err, size_t err_len) {
    if (writer == nullptr || origin == nullptr || dims == nullptr || data == nullptr ||
        writer->grids.empty()) {
        set_err(err, err_len, "bad argument to grin_vdb_writer_add_box (no grid added yet?)");
        return GRIN_VDB_ERR_ARG;
    }
    int32_t bmax[3];
    if (!box_max(origin, dims, bmax)) {
        set_err(err, err_len, "box dimensions out of range");
        return GRIN_VDB_ERR_ARG;
    }
    const uint64_t n = box_voxels(origin, bmax);
    openvdb::GridBase& base = *writer->grids.back();
    const uint64_t components = base.isType<openvdb::Vec3SGrid>() ? 3 : 1;
    if (n == 0 || n * components != data_len) {
        set_err(err, err_len, "data length does not match the box dimensions");
        return GRIN_VDB_ERR_ARG;
    }
    return guarded(err, err_len, [&]() {
        copy_box(base, make_box(origin, bmax), data, tolerance);
        return static_cast<int>(GRIN_VDB_OK);
    });
}

int grin_vdb_writer_add_file_meta(GrinVdbWriter* writer, const char* key, const char* value,
                                  char* err, size_t err_len) {
    if (writer == nullptr || key == nullptr || value == nullptr) {
        set_err(err, err_len, "null argument");
        return GRIN_VDB_ERR_ARG;
    }
    return guarded(err, err_len, [&]() {
        writer->file_meta.insertMeta(key, openvdb::StringMetadata(value));
        return static_cast<int>(GRIN_VDB_OK);
    });
}

int grin_vdb_writer_write(GrinVdbWriter* writer, const char* path, char* err, size_t err_len) {
    if (writer == nullptr || path == nullptr) {
        set_err(err, err_len, "null argument");
        return GRIN_VDB_ERR_ARG;
    }
    return guarded(err, err_len, [&]() {
        openvdb::io::File f(path);
        f.write(writer->grids, writer->file_meta);
        f.close();
        return static_cast<int>(GRIN_VDB_OK);
    });
}

}  // extern "C"
