// grin_vdb_check.cpp: a tiny executable that opens a .vdb file through the shim and reads
// every grid, so that vdb-sys can try a file in a child process first. OpenVDB can corrupt
// the heap (and abort) on some malformed files; in a child that is an exit status, not a
// crash of grin. Exit 0: readable; 1: a reported error (message on stderr); 2: usage.

#include "grin_vdb.h"

#include <cstdio>
#include <cstdlib>
#include <vector>

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: grin-vdb-check FILE MAX_DENSE_BYTES\n");
        return 2;
    }
    const unsigned long long cap = std::strtoull(argv[2], nullptr, 10);
    char err[1024] = {0};
    GrinVdbFile* file = nullptr;
    if (grin_vdb_open(argv[1], &file, err, sizeof err) != GRIN_VDB_OK) {
        std::fprintf(stderr, "%s\n", err);
        return 1;
    }
    const size_t n = grin_vdb_grid_count(file);
    for (size_t g = 0; g < n; ++g) {
        GrinVdbGridInfo info;
        if (grin_vdb_grid_info(file, g, &info, err, sizeof err) != GRIN_VDB_OK) {
            std::fprintf(stderr, "%s\n", err);
            return 1;
        }
        if (info.is_empty) continue;
        unsigned long long voxels = 1;
        bool too_big = false;
        for (int a = 0; a < 3; ++a) {
            const unsigned long long d =
                static_cast<unsigned long long>(static_cast<long long>(info.bbox_max[a]) -
                                                info.bbox_min[a] + 1);
            if (voxels > cap / (d ? d : 1)) too_big = true;
            voxels *= d;
        }
        const bool scalar = info.type_code == GRIN_VDB_TYPE_FLOAT ||
                            info.type_code == GRIN_VDB_TYPE_DOUBLE;
        const bool vec = info.type_code == GRIN_VDB_TYPE_VEC3S ||
                         info.type_code == GRIN_VDB_TYPE_VEC3D;
        const unsigned long long comps = vec ? 3 : 1;
        if (too_big || voxels * comps * sizeof(float) > cap || (!scalar && !vec)) continue;
        std::vector<float> buf(voxels * comps);
        const int status =
            scalar ? grin_vdb_read_scalar(file, g, info.bbox_min, info.bbox_max, buf.data(),
                                          buf.size(), err, sizeof err)
                   : grin_vdb_read_vec3(file, g, info.bbox_min, info.bbox_max, buf.data(),
                                        buf.size(), err, sizeof err);
        if (status != GRIN_VDB_OK) {
            std::fprintf(stderr, "%s\n", err);
            return 1;
        }
    }
    grin_vdb_close(file);
    return 0;
}
