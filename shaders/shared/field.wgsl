// The baked field on the GPU: n and grad n from the 3D texture, and the macro-cell walk.
// CPU twin: grin_field::baked::BakedField::{sample, homogeneous_span} and
// grin_field::baked::MacroGrid::span.
//
// Texels hold (delta_n, dn/dx, dn/dy, dn/dz) at the grid nodes: f32 (rgba32float), or
// i16 / 32767 (rgba16snorm, FLAG_FIELD_SNORM) scaled by params.field_scale after the blend.
// Interpolation is done here with textureLoad, not by the sampler: float32 filtering
// needs the optional FLOAT32_FILTERABLE feature, and hardware filter weights may have
// only 8 fractional bits; manual trilinear matches the CPU's weights exactly.

struct FieldSample {
    n: f32,
    grad_n: vec3<f32>,
    delta_n: f32,
}

fn ambient_index() -> f32 {
    return params.ambient_n;
}

fn grid_from_world_point(p: vec3<f32>) -> vec3<f32> {
    return (p - params.grid_origin) * params.grid_inv_spacing;
}

fn grid_max() -> vec3<f32> {
    return vec3<f32>(params.grid_dims - vec3<u32>(1u));
}

fn beyond_grid(g: vec3<f32>) -> bool {
    return any(g < vec3<f32>(0.0)) || any(g > grid_max());
}

fn voxel(i: i32, j: i32, k: i32) -> vec4<f32> {
    return textureLoad(field_tex, vec3<i32>(i, j, k), 0);
}

fn trilinear(g: vec3<f32>) -> vec4<f32> {
    let d = vec3<i32>(params.grid_dims);
    let base = min(vec3<i32>(floor(g)), d - vec3<i32>(2));
    let t = g - vec3<f32>(base);
    let c000 = voxel(base.x, base.y, base.z);
    let c100 = voxel(base.x + 1, base.y, base.z);
    let c010 = voxel(base.x, base.y + 1, base.z);
    let c110 = voxel(base.x + 1, base.y + 1, base.z);
    let c001 = voxel(base.x, base.y, base.z + 1);
    let c101 = voxel(base.x + 1, base.y, base.z + 1);
    let c011 = voxel(base.x, base.y + 1, base.z + 1);
    let c111 = voxel(base.x + 1, base.y + 1, base.z + 1);
    let x00 = mix(c000, c100, t.x);
    let x10 = mix(c010, c110, t.x);
    let x01 = mix(c001, c101, t.x);
    let x11 = mix(c011, c111, t.x);
    let v = mix(mix(x00, x10, t.y), mix(x01, x11, t.y), t.z);
    if (FLAGS & FLAG_FIELD_SNORM) != 0u {
        return v * params.field_scale;
    }
    return v;
}

// Uniform cubic B-spline weights at fraction t (bspline::weights).
fn bspline_weights(t: f32) -> vec4<f32> {
    let s = 1.0 - t;
    let t2 = t * t;
    let t3 = t2 * t;
    return vec4<f32>(s * s * s / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0, (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t3 / 6.0);
}

// Mirror boundary for spline taps (bspline::mirror).
fn mirror_index(i: i32, n: i32) -> i32 {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    var m = i % period;
    if m < 0 {
        m += period;
    }
    return select(m, period - m, m >= n);
}

// The tricubic sum is written out without loops, in the order of the CPU twin's loops
// (z outer, then y, then x lines): lavapipe (Mesa's gallivm) stops every loop of a shader
// invocation after 65535 iterations in all (LP_MAX_TGSI_LOOP_ITERATIONS, shared by every
// loop), and the 4x4x4 loops here spent ~20 of them per sample, ending rays of more than
// ~2300 samples as `error` (the GPU column of `grin bench accuracy`).
fn mirror4(b: i32, n: i32) -> vec4<i32> {
    return vec4<i32>(mirror_index(b, n), mirror_index(b + 1, n), mirror_index(b + 2, n), mirror_index(b + 3, n));
}

// One line of 4 coefficients along x, weighted, then the line times its y-z weight
// (BakedField::tricubic's order: fewer roundings at the sum's full size than adding the
// 64 weighted coefficients one by one, which left the GPU's error floor on an f32
// tricubic grid 2-5x the CPU twin's in `grin bench accuracy`).
fn tricubic_line(ix: vec4<i32>, j: i32, k: i32, wx: vec4<f32>) -> vec4<f32> {
    var line = voxel(ix.x, j, k) * wx.x;
    line += voxel(ix.y, j, k) * wx.y;
    line += voxel(ix.z, j, k) * wx.z;
    line += voxel(ix.w, j, k) * wx.w;
    return line;
}

fn tricubic_plane(acc: vec4<f32>, ix: vec4<i32>, iy: vec4<i32>, k: i32, wz: f32, wx: vec4<f32>, wy: vec4<f32>) -> vec4<f32> {
    var out = acc;
    out += tricubic_line(ix, iy.x, k, wx) * (wz * wy.x);
    out += tricubic_line(ix, iy.y, k, wx) * (wz * wy.y);
    out += tricubic_line(ix, iy.z, k, wx) * (wz * wy.z);
    out += tricubic_line(ix, iy.w, k, wx) * (wz * wy.w);
    return out;
}

fn tricubic(g: vec3<f32>) -> vec4<f32> {
    let d = vec3<i32>(params.grid_dims);
    let fl = floor(g);
    let wx = bspline_weights(g.x - fl.x);
    let wy = bspline_weights(g.y - fl.y);
    let wz = bspline_weights(g.z - fl.z);
    let b = vec3<i32>(fl) - vec3<i32>(1);
    let ix = mirror4(b.x, d.x);
    let iy = mirror4(b.y, d.y);
    let iz = mirror4(b.z, d.z);
    var out = vec4<f32>(0.0);
    out = tricubic_plane(out, ix, iy, iz.x, wz.x, wx, wy);
    out = tricubic_plane(out, ix, iy, iz.y, wz.y, wx, wy);
    out = tricubic_plane(out, ix, iy, iz.z, wz.z, wx, wy);
    out = tricubic_plane(out, ix, iy, iz.w, wz.w, wx, wy);
    return out;
}

// ---- Sparse bakes (grin_field::sparse::SparseField::sample) ----
//
// macro_tex is the brick table, one texel per top brick: (cells a brick edge, first voxel
// / 65536, first voxel % 65536, most cells a side among it and its 26 neighbours), with 0
// cells for an empty brick (so the macro-cell test flies over it). Where the voxels are
// i16 (FLAG_FIELD_SNORM), a second block of as many texels follows in z: each brick's
// scales (delta_n, gradient), times 32767.
// field_tex is a linear array of texels, SPARSE_ROW x SPARSE_ROW a layer: every active
// brick's (cells + 1)^3 nodes, x fastest, in f32 or rgba16snorm (q / 32767); with
// FLAG_TRICUBIC (Catmull-Rom) (cells + 3)^3, one node beyond each face (the apron), node
// i of the brick's cells stored at i + 1.
// The grid parameters place the top grid: grid_origin its corner, grid_inv_spacing 1 /
// brick edge, grid_dims bricks + 1.

const SPARSE_ROW: u32 = 256u;

fn linear_texel(t: u32) -> vec4<f32> {
    return textureLoad(field_tex, vec3<i32>(i32(t % SPARSE_ROW), i32((t / SPARSE_ROW) % SPARSE_ROW), i32(t / (SPARSE_ROW * SPARSE_ROW))), 0);
}

// The table texel of the top-grid brick holding grid point g (the nearest brick where g
// is beyond the grid; SparseField's TopGrid::brick_holding), and that brick.
struct SparseBrick {
    at: vec3<u32>,
    entry: vec4<f32>,
}

fn sparse_brick(g: vec3<f32>) -> SparseBrick {
    let bricks = params.grid_dims - vec3<u32>(1u);
    let b = min(vec3<u32>(max(floor(g), vec3<f32>(0.0))), bricks - vec3<u32>(1u));
    return SparseBrick(b, textureLoad(macro_tex, vec3<i32>(b), 0));
}

fn sparse_sample(p: vec3<f32>) -> FieldSample {
    let g = grid_from_world_point(p);
    let ambient = FieldSample(ambient_index(), vec3<f32>(0.0), 0.0);
    if beyond_grid(g) {
        return ambient;
    }
    let brick = sparse_brick(g);
    let b = brick.at;
    let entry = brick.entry;
    if entry.x < 1.0 {
        return ambient;
    }
    let cells = u32(entry.x);
    let tricubic = (FLAGS & FLAG_TRICUBIC) != 0u;
    let m = select(cells + 1u, cells + 3u, tricubic);
    let u = clamp((g - vec3<f32>(b)) * f32(cells), vec3<f32>(0.0), vec3<f32>(f32(cells)));
    let i = min(vec3<u32>(u), vec3<u32>(cells - 1u));
    let t = u - vec3<f32>(i);
    // Trilinear: node i; Catmull-Rom: node i - 1, stored at i.
    let first = u32(entry.y) * 65536u + u32(entry.z) + i.x + m * (i.y + m * i.z);
    var v: vec4<f32>;
    let of_n = (FLAGS & FLAG_GRADIENT_OF_N) != 0u;
    if of_n {
        v = sparse_catmull_rom_n(first, m, t);
    } else if tricubic {
        v = sparse_catmull_rom(first, m, t);
    } else {
        v = sparse_trilinear(first, m, t);
    }
    if (FLAGS & FLAG_FIELD_SNORM) != 0u {
        let bricks = params.grid_dims - vec3<u32>(1u);
        let s = textureLoad(macro_tex, vec3<i32>(b + vec3<u32>(0u, 0u, bricks.z)), 0);
        v = v * select(s.xyyy, s.xxxx, of_n);
    }
    if of_n {
        // Cell units to world: a cell is the brick edge / cells.
        let per_cell = f32(cells) * params.grid_inv_spacing.x;
        v = v * vec4<f32>(1.0, per_cell, per_cell, per_cell);
    }
    // Catmull-Rom rings past a sharp edge: delta_n is clamped to the nodes' range
    // (params.field_scale.xy for a sparse bake), flat where clamped.
    if tricubic && (v.x < params.field_scale.x || v.x > params.field_scale.y) {
        let d = clamp(v.x, params.field_scale.x, params.field_scale.y);
        return FieldSample(ambient_index() + d, vec3<f32>(0.0), d);
    }
    return FieldSample(ambient_index() + v.x, v.yzw, v.x);
}

// Trilinear blend of a brick's 8 nodes from `first` (m nodes a row).
fn sparse_trilinear(first: u32, m: u32, t: vec3<f32>) -> vec4<f32> {
    let c000 = linear_texel(first);
    let c100 = linear_texel(first + 1u);
    let c010 = linear_texel(first + m);
    let c110 = linear_texel(first + m + 1u);
    let c001 = linear_texel(first + m * m);
    let c101 = linear_texel(first + m * m + 1u);
    let c011 = linear_texel(first + m * m + m);
    let c111 = linear_texel(first + m * m + m + 1u);
    let x00 = mix(c000, c100, t.x);
    let x10 = mix(c010, c110, t.x);
    let x01 = mix(c001, c101, t.x);
    let x11 = mix(c011, c111, t.x);
    return mix(mix(x00, x10, t.y), mix(x01, x11, t.y), t.z);
}

// Catmull-Rom weights at fraction t (grin_field::sparse::catmull_rom_weights).
fn catmull_rom_weights(t: f32) -> vec4<f32> {
    let t2 = t * t;
    let t3 = t2 * t;
    return vec4<f32>(0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2));
}

// One line of 4 nodes along x from `first`, weighted.
fn sparse_cr_line(first: u32, wx: vec4<f32>) -> vec4<f32> {
    var line = linear_texel(first) * wx.x;
    line += linear_texel(first + 1u) * wx.y;
    line += linear_texel(first + 2u) * wx.z;
    line += linear_texel(first + 3u) * wx.w;
    return line;
}

// The 4 lines of one z plane from `first`, each times its y-z weight, added to `acc`.
fn sparse_cr_plane(acc: vec4<f32>, first: u32, m: u32, wz: f32, wx: vec4<f32>, wy: vec4<f32>) -> vec4<f32> {
    var out = acc;
    out += sparse_cr_line(first, wx) * (wz * wy.x);
    out += sparse_cr_line(first + m, wx) * (wz * wy.y);
    out += sparse_cr_line(first + 2u * m, wx) * (wz * wy.z);
    out += sparse_cr_line(first + 3u * m, wx) * (wz * wy.w);
    return out;
}

// Tricubic Catmull-Rom of a brick's 4 x 4 x 4 nodes from `first` (m nodes a row), in the
// CPU twin's order (SparseField::catmull_rom: z planes, then y lines), written out without
// loops (lavapipe's loop-iteration limit: see `tricubic`).
fn sparse_catmull_rom(first: u32, m: u32, t: vec3<f32>) -> vec4<f32> {
    let wx = catmull_rom_weights(t.x);
    let wy = catmull_rom_weights(t.y);
    let wz = catmull_rom_weights(t.z);
    let plane = m * m;
    var v = vec4<f32>(0.0);
    v = sparse_cr_plane(v, first, m, wz.x, wx, wy);
    v = sparse_cr_plane(v, first + plane, m, wz.y, wx, wy);
    v = sparse_cr_plane(v, first + 2u * plane, m, wz.z, wx, wy);
    v = sparse_cr_plane(v, first + 3u * plane, m, wz.w, wx, wy);
    return v;
}

// d/dt of catmull_rom_weights (grin_field::sparse::catmull_rom_derivatives).
fn catmull_rom_derivatives(t: f32) -> vec4<f32> {
    let t2 = t * t;
    return vec4<f32>(0.5 * (-(3.0 * t2) + 4.0 * t - 1.0), 0.5 * (9.0 * t2 - 10.0 * t), 0.5 * (-(9.0 * t2) + 8.0 * t + 1.0), 0.5 * (3.0 * t2 - 2.0 * t));
}

// One line of 4 nodes' delta_n along x from `first`: its value and x derivative.
fn sparse_cr_line_n(first: u32, wx: vec4<f32>, dx: vec4<f32>) -> vec2<f32> {
    let f = vec4<f32>(linear_texel(first).x, linear_texel(first + 1u).x, linear_texel(first + 2u).x, linear_texel(first + 3u).x);
    let v = f.x * wx.x + f.y * wx.y + f.z * wx.z + f.w * wx.w;
    let d = f.x * dx.x + f.y * dx.y + f.z * dx.z + f.w * dx.w;
    return vec2<f32>(v, d);
}

// Line `l` (value, x derivative) of a z plane, added to `acc` as (delta_n, d/dx, d/dy,
// d/dz) in cell units with the plane's weights wz, dz and the line's wy, dy.
fn sparse_cr_add_n(acc: vec4<f32>, l: vec2<f32>, wz: f32, dz: f32, wy: f32, dy: f32) -> vec4<f32> {
    return acc + vec4<f32>(l.x, l.y, l.x, l.x) * vec4<f32>(wz * wy, wz * wy, wz * dy, dz * wy);
}

// The 4 lines of one z plane from `first` of delta_n alone, added to `acc`
// (SparseField::catmull_rom with its gradient of n, in its order; no loop: see `tricubic`).
fn sparse_cr_plane_n(acc: vec4<f32>, first: u32, m: u32, wz: f32, dz: f32, wx: vec4<f32>, dx: vec4<f32>, wy: vec4<f32>, dy: vec4<f32>) -> vec4<f32> {
    var out = sparse_cr_add_n(acc, sparse_cr_line_n(first, wx, dx), wz, dz, wy.x, dy.x);
    out = sparse_cr_add_n(out, sparse_cr_line_n(first + m, wx, dx), wz, dz, wy.y, dy.y);
    out = sparse_cr_add_n(out, sparse_cr_line_n(first + 2u * m, wx, dx), wz, dz, wy.z, dy.z);
    out = sparse_cr_add_n(out, sparse_cr_line_n(first + 3u * m, wx, dx), wz, dz, wy.w, dy.w);
    return out;
}

// Catmull-Rom delta_n of a brick's 4 x 4 x 4 nodes from `first` and its derivative in cell
// units: the gradient of n where the field's is (FLAG_GRADIENT_OF_N).
fn sparse_catmull_rom_n(first: u32, m: u32, t: vec3<f32>) -> vec4<f32> {
    let wx = catmull_rom_weights(t.x);
    let wy = catmull_rom_weights(t.y);
    let wz = catmull_rom_weights(t.z);
    let dx = catmull_rom_derivatives(t.x);
    let dy = catmull_rom_derivatives(t.y);
    let dz = catmull_rom_derivatives(t.z);
    let plane = m * m;
    var v = vec4<f32>(0.0);
    v = sparse_cr_plane_n(v, first, m, wz.x, dz.x, wx, dx, wy, dy);
    v = sparse_cr_plane_n(v, first + plane, m, wz.y, dz.y, wx, dx, wy, dy);
    v = sparse_cr_plane_n(v, first + 2u * plane, m, wz.z, dz.z, wx, dx, wy, dy);
    v = sparse_cr_plane_n(v, first + 3u * plane, m, wz.w, dz.w, wx, dx, wy, dy);
    return v;
}

// The local step cap (SparseField::step_cap): twice the spacing of the finest brick in
// and next to the brick holding p (the table texel's w), one brick edge where none is
// active.
fn sparse_step_cap(p: vec3<f32>) -> f32 {
    let near = sparse_brick(grid_from_world_point(p)).entry.w;
    let edge = 1.0 / params.grid_inv_spacing.x;
    if near < 1.0 {
        return edge;
    }
    return 2.0 * edge / near;
}

fn sample_field(p: vec3<f32>) -> FieldSample {
    if (FLAGS & FLAG_SPARSE) != 0u {
        return sparse_sample(p);
    }
    let g = grid_from_world_point(p);
    if (FLAGS & FLAG_OUTSIDE_AMBIENT) != 0u && beyond_grid(g) {
        return FieldSample(ambient_index(), vec3<f32>(0.0), 0.0);
    }
    let gc = clamp(g, vec3<f32>(0.0), grid_max());
    var v: vec4<f32>;
    if (FLAGS & FLAG_TRICUBIC) != 0u {
        v = tricubic(gc);
    } else {
        v = trilinear(gc);
    }
    return FieldSample(ambient_index() + v.x, v.yzw, v.x);
}

// ---- Macro cells (the paper's "infinite step") ----

fn macro_homogeneous(c: vec3<i32>) -> bool {
    return textureLoad(macro_tex, c, 0).x <= params.macro_threshold;
}

// The macro cell holding grid point g (clamped into the grid).
fn macro_cell(g: vec3<f32>) -> vec3<i32> {
    let gc = clamp(g, vec3<f32>(0.0), grid_max()) / f32(params.macro_cell_voxels);
    return min(vec3<i32>(max(floor(gc), vec3<f32>(0.0))), vec3<i32>(params.macro_dims) - vec3<i32>(1));
}

// From grid point g along grid direction dg: world length to the end of the run of
// homogeneous cells starting at g's cell; negative if that cell varies (MacroGrid::span).
fn macro_span(g: vec3<f32>, dg: vec3<f32>) -> f32 {
    let cell = f32(params.macro_cell_voxels);
    let mdims = vec3<i32>(params.macro_dims);
    let gmax = grid_max();
    var c = macro_cell(g);
    if !macro_homogeneous(c) {
        return -1.0;
    }
    var s_next = vec3<f32>(INF);
    var s_delta = vec3<f32>(INF);
    var stp = vec3<i32>(0);
    for (var a = 0; a < 3; a++) {
        if dg[a] > 0.0 {
            stp[a] = 1;
            s_next[a] = (max(min(f32(c[a] + 1) * cell, gmax[a]), g[a]) - g[a]) / dg[a];
            s_delta[a] = cell / dg[a];
        } else if dg[a] < 0.0 {
            stp[a] = -1;
            s_next[a] = max(g[a] - f32(c[a]) * cell, 0.0) / -dg[a];
            s_delta[a] = cell / -dg[a];
        }
    }
    let max_cells = mdims.x + mdims.y + mdims.z;
    for (var i = 0; i < max_cells; i++) {
        var a = 2;
        if s_next.x <= s_next.y && s_next.x <= s_next.z {
            a = 0;
        } else if s_next.y <= s_next.z {
            a = 1;
        }
        let s = s_next[a];
        if s >= INF {
            return -1.0;
        }
        let next = c[a] + stp[a];
        if next < 0 {
            return s;
        }
        if next >= mdims[a] {
            return min(s, max(gmax[a] - g[a], 0.0) / dg[a]);
        }
        c[a] = next;
        if !macro_homogeneous(c) {
            return s;
        }
        s_next[a] += s_delta[a];
    }
    return -1.0;
}

// The cheap part of homogeneous_span: false where it certainly returns -1 (inside the
// grid in a varying macro cell, or beyond the grid when that is not ambient). The
// marcher walks the cells only where this is true.
fn may_fly(p: vec3<f32>) -> bool {
    let g = grid_from_world_point(p);
    if beyond_grid(g) {
        return (FLAGS & FLAG_OUTSIDE_AMBIENT) != 0u;
    }
    return macro_homogeneous(macro_cell(g));
}

// BakedField::homogeneous_span: positive world length of a straight flight, or -1.
fn homogeneous_span(p: vec3<f32>, dir: vec3<f32>) -> f32 {
    let g = grid_from_world_point(p);
    let dg = dir * params.grid_inv_spacing;
    var span = -1.0;
    if beyond_grid(g) {
        if (FLAGS & FLAG_OUTSIDE_AMBIENT) == 0u {
            return -1.0;
        }
        let lo = params.grid_origin;
        let hi = lo + grid_max() / params.grid_inv_spacing;
        let to_grid = box_interval(lo, hi, p, dir);
        let to_exit = bounds_intersect(p, dir);
        if to_grid.found && to_exit.found {
            span = min(max(to_grid.s_in, 0.0), max(to_exit.s_out, 0.0));
        } else if to_grid.found {
            span = max(to_grid.s_in, 0.0);
        } else if to_exit.found {
            span = max(to_exit.s_out, 0.0);
        }
    } else {
        span = macro_span(g, dg);
    }
    return select(-1.0, span, span > 0.0);
}
