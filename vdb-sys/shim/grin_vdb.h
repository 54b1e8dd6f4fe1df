/* grin_vdb.h: the extern "C" surface of grin's OpenVDB shim (grin_vdb.cpp).
 *
 * Every function that can fail returns a status (GRIN_VDB_OK or an error code) and
 * writes a NUL-terminated message into the caller's `err` buffer. No C++ exception
 * crosses this boundary. Keep in sync with vdb-sys/src/ffi.rs.
 */
#ifndef GRIN_VDB_H
#define GRIN_VDB_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

enum {
    GRIN_VDB_OK = 0,
    GRIN_VDB_ERR_IO = 1,        /* missing/unreadable/corrupt file */
    GRIN_VDB_ERR_ARG = 2,       /* bad index, wrong buffer size, wrong grid type */
    GRIN_VDB_ERR_MEMORY = 3,    /* std::bad_alloc */
    GRIN_VDB_ERR_OTHER = 4      /* any other exception */
};

/* Value types the dense readers understand. */
enum {
    GRIN_VDB_TYPE_OTHER = 0,
    GRIN_VDB_TYPE_FLOAT = 1,
    GRIN_VDB_TYPE_DOUBLE = 2,
    GRIN_VDB_TYPE_VEC3S = 3,
    GRIN_VDB_TYPE_VEC3D = 4
};

/* Metadata kinds. */
enum {
    GRIN_VDB_META_OTHER = 0,
    GRIN_VDB_META_STRING = 1,
    GRIN_VDB_META_NUMBER = 2
};

typedef struct GrinVdbFile GrinVdbFile;
typedef struct GrinVdbWriter GrinVdbWriter;

/* Summary of one grid. Strings are owned by the file handle. */
typedef struct GrinVdbGridInfo {
    const char* name;
    const char* value_type;      /* OpenVDB type name: "float", "vec3s", ... */
    const char* grid_class;      /* "fog volume", "level set", "unknown", ... */
    const char* map_type;        /* "UniformScaleTranslateMap", "FrustumMap", ... */
    int32_t type_code;           /* GRIN_VDB_TYPE_* */
    int32_t is_linear;           /* transform is affine */
    int32_t save_float_as_half;  /* stored as 16-bit floats */
    int32_t is_empty;            /* no active voxels */
    double voxel_size[3];
    /* world = A * ijk + t as a row-major 3x4 matrix [A | t] (column-vector convention). */
    double world_from_index[12];
    int32_t bbox_min[3];         /* active-voxel bounding box, inclusive (index space) */
    int32_t bbox_max[3];
    uint64_t active_voxel_count;
    uint64_t non_finite_count;   /* active voxels (scalar or any component) NaN/Inf */
    double value_min;            /* over finite active values; |v| for vectors */
    double value_max;
    double background;           /* scalar grids; |background| for vectors */
    size_t meta_count;
    /* Scalar grids: bounding box (inclusive) of the active voxels whose value differs from
     * the background (NaN/Inf included), and their count; max < min when there are none. */
    int32_t data_min[3];
    int32_t data_max[3];
    uint64_t data_voxel_count;
} GrinVdbGridInfo;

/* Open a file and read all of its grids. */
int grin_vdb_open(const char* path, GrinVdbFile** out, char* err, size_t err_len);
void grin_vdb_close(GrinVdbFile* file);

size_t grin_vdb_grid_count(const GrinVdbFile* file);
int grin_vdb_grid_info(const GrinVdbFile* file, size_t grid, GrinVdbGridInfo* out,
                       char* err, size_t err_len);

/* File metadata (grid == SIZE_MAX) or a grid's metadata, entry i. Strings owned by file. */
size_t grin_vdb_file_meta_count(const GrinVdbFile* file);
int grin_vdb_meta(const GrinVdbFile* file, size_t grid, size_t i, const char** key,
                  const char** type_name, int32_t* kind, const char** text, double* number,
                  char* err, size_t err_len);

/* Copy the inclusive index box [bmin, bmax] of a scalar (float or double) grid into
 * `out` (x fastest, then y, then z); out_len must equal the box's voxel count. */
int grin_vdb_read_scalar(const GrinVdbFile* file, size_t grid, const int32_t bmin[3],
                         const int32_t bmax[3], float* out, size_t out_len, char* err,
                         size_t err_len);
/* The same for vec3 grids: out holds 3 floats per voxel, out_len = 3 * voxel count. */
int grin_vdb_read_vec3(const GrinVdbFile* file, size_t grid, const int32_t bmin[3],
                       const int32_t bmax[3], float* out, size_t out_len, char* err,
                       size_t err_len);

/* Writing: a writer collects grids and file metadata, then writes one file. */
GrinVdbWriter* grin_vdb_writer_new(void);
void grin_vdb_writer_free(GrinVdbWriter* writer);
/* Add a grid from a dense box of `dims` voxels starting at index `origin` (x fastest).
 * components = 1 (float grid) or 3 (vec3s grid). Values equal to `background` within
 * `tolerance` become inactive. meta_* are n_meta string entries and n_num numbers. */
int grin_vdb_writer_add_grid(GrinVdbWriter* writer, const char* name, int32_t components,
                             const int32_t origin[3], const uint64_t dims[3],
                             const float* data, size_t data_len,
                             const double world_from_index[12], float background,
                             float tolerance, int32_t save_as_half,
                             const char* const* meta_keys, const char* const* meta_values,
                             size_t n_meta, const char* const* num_keys,
                             const double* num_values, size_t n_num, char* err,
                             size_t err_len);
/* Copy one more dense box into the grid added last (its other voxels kept): a sparse
 * grid written box by box. data as for grin_vdb_writer_add_grid. */
int grin_vdb_writer_add_box(GrinVdbWriter* writer, const int32_t origin[3],
                            const uint64_t dims[3], const float* data, size_t data_len,
                            float tolerance, char* err, size_t err_len);
int grin_vdb_writer_add_file_meta(GrinVdbWriter* writer, const char* key, const char* value,
                                  char* err, size_t err_len);
int grin_vdb_writer_write(GrinVdbWriter* writer, const char* path, char* err, size_t err_len);

#ifdef __cplusplus
}
#endif

#endif
