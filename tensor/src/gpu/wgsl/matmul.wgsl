// out[b] (+)= op(A_b) @ op(B_b) for each batch entry b, then optionally + bias and an
// activation (ops/matmul.rs). op(A) is m x k (`a` holds A, or A^T when ta), op(B) is k x n
// (likewise with tb), all row-major; the output is [batches, m, n].
//
// p = [m, k, n, ta, tb, accumulate, has_bias, act (0 identity, 1 relu, 2 tanh), batches,
//      a_base, b_base, a_stride, b_stride, offsets_listed, out_base, ldb, ldo, bias_base,
//      tiles_n, tiles_per_batch, slices, k_per_slice]: batch entry b's matrices start at
//      `offsets` (when listed) or at base + b * stride (ops/matmul.rs: no upload when the
//      offsets are regular), its output at out_base + b * m * n; the stored rows of B are ldb
//      apart and the output's ldo (more than their width for a block of columns of a weight
//      or of its gradient; one product then), the bias starts at bias_base; the first 18 are
//      matmul_small.wgsl's.
//
// Split k (slices > 1, ops/matmul.rs: few output tiles over a long inner dim): slice s sums
// k in [s * k_per_slice, (s + 1) * k_per_slice) and writes its partial sums, with no
// epilogue, to out[s * batches * m * n ..]; matmul_reduce.wgsl then adds the slices in
// order and applies the epilogue. The order of the sum is fixed by the shapes, so a product
// still has the same bits on every run.
//
// Tiling: a workgroup of 16 x 16 threads computes a TILE_M x 64 tile of one batch entry's
// output, each thread a MICRO_M x 4 micro-tile (rows MICRO_M*ty.., columns 4*tx..). MICRO_M
// is 4 (64 x 64 tiles) or 8 (128 x 64 tiles, fewer loads from workgroup memory per product),
// set by the file before this one (matmul_tile_64.wgsl, matmul_tile_128.wgsl; ops/matmul.rs
// picks). The inner dim goes in steps of 16: the workgroup loads the TILE_M x 16 block of
// op(A) and the 16 x 64 block of op(B) into workgroup memory (out-of-range values as 0), then
// each thread adds the products of that step. Every output element is summed by one thread
// over k in increasing order (no atomics; a split of k is fixed by the shapes, not by the
// tile), so the result has the same bits on every run, and with either tile.

// The workgroups are numbered linearly (wg.x + wg.y * num_workgroups.x, see Gpu::launch): the
// slice, the batch entry, then the tile row, then the tile column.
//
// The accumulators are MICRO_M vec4 registers (c0..c7, the last four only with MICRO_M 8),
// never indexed by a runtime value: an array indexed at run time is placed in (slow) local
// memory by GPU compilers. Full steps of k run a loop of constant length (unrolled); only
// the last, partial step loops over fewer.
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
// (offset of A_b, offset of B_b) in elements, per batch entry (MatMulPlan::offsets).
@group(0) @binding(3) var<storage, read> offsets: array<u32>;
// [n] values added to every row when has_bias (any buffer otherwise: never read).
@group(0) @binding(4) var<storage, read> bias: array<f32>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;

const TILE_M: u32 = 16u * MICRO_M;
const TILE_N: u32 = 64u;
const TILE_K: u32 = 16u;
// vec4s per k-row of a workgroup tile: TILE_M / 4 (TILE_N / 4) hold the values, 1 of
// padding spreads the stores of the cooperative loads over the memory banks.
const ROW_VEC4_A: u32 = TILE_M / 4u + 1u;
const ROW_VEC4_B: u32 = TILE_N / 4u + 1u;
// Values of each block a thread loads per step of k (256 threads).
const LOADS_A: u32 = TILE_M * TILE_K / 256u;
const LOADS_B: u32 = TILE_N * TILE_K / 256u;

// tile_a[kk * ROW_VEC4_A + r / 4][r % 4] = op(A)[row0 + r, k0 + kk]
var<workgroup> tile_a: array<vec4<f32>, TILE_K * ROW_VEC4_A>;
// tile_b[kk * ROW_VEC4_B + c / 4][c % 4] = op(B)[k0 + kk, col0 + c]
var<workgroup> tile_b: array<vec4<f32>, TILE_K * ROW_VEC4_B>;

// acc rows: output (row0 + MICRO_M ty + i, col0 + 4 tx ..) for i = 0..MICRO_M-1.
var<private> c0: vec4<f32>;
var<private> c1: vec4<f32>;
var<private> c2: vec4<f32>;
var<private> c3: vec4<f32>;
var<private> c4: vec4<f32>;
var<private> c5: vec4<f32>;
var<private> c6: vec4<f32>;
var<private> c7: vec4<f32>;

// The products of one k of the workgroup tiles.
fn mac(kk: u32, tx: u32, ty: u32) {
    let row = kk * ROW_VEC4_A + (MICRO_M / 4u) * ty;
    let bv = tile_b[kk * ROW_VEC4_B + tx];
    let av = tile_a[row];
    c0 = fma(vec4<f32>(av.x), bv, c0);
    c1 = fma(vec4<f32>(av.y), bv, c1);
    c2 = fma(vec4<f32>(av.z), bv, c2);
    c3 = fma(vec4<f32>(av.w), bv, c3);
    if MICRO_M == 8u {
        let aw = tile_a[row + 1u];
        c4 = fma(vec4<f32>(aw.x), bv, c4);
        c5 = fma(vec4<f32>(aw.y), bv, c5);
        c6 = fma(vec4<f32>(aw.z), bv, c6);
        c7 = fma(vec4<f32>(aw.w), bv, c7);
    }
}

// Epilogue of one output row: (+ the current value) + bias, activation; one store per element.
fn store_row(r: u32, c: u32, n: u32, base: u32, v: vec4<f32>, accumulate: bool, has_bias: bool, code: u32) {
    let ldo = p[16];
    for (var j = 0u; j < 4u; j++) {
        if c + j >= n {
            break;
        }
        let idx = base + r * ldo + c + j;
        var x = v.x;
        if j == 1u { x = v.y; } else if j == 2u { x = v.z; } else if j == 3u { x = v.w; }
        if accumulate {
            x = out[idx] + x;
        }
        if has_bias {
            x = x + bias[p[17] + c + j];
        }
        out[idx] = activation(code, x);
    }
}

@compute @workgroup_size(16, 16)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_id) lid: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let m = p[0];
    let k = p[1];
    let n = p[2];
    let ta = p[3] != 0u;
    let tb = p[4] != 0u;
    let batches = p[8];
    let tiles_n = p[18];
    let per_batch = p[19];
    let slices = p[20];
    let k_per_slice = p[21];
    let wid = wg.x + wg.y * nwg.x;
    // The grid may hold a few more workgroups than tiles (Gpu::launch rounds up to a
    // rectangle); the test is the same for the whole workgroup.
    if wid >= per_batch * batches * slices {
        return;
    }
    let slice = wid / (per_batch * batches);
    let batch = (wid / per_batch) % batches;
    let tile = wid % per_batch;
    let row0 = (tile / tiles_n) * TILE_M;
    let col0 = (tile % tiles_n) * TILE_N;
    var a_off = p[9] + batch * p[11];
    var b_off = p[10] + batch * p[12];
    if p[13] != 0u {
        a_off = offsets[2u * batch];
        b_off = offsets[2u * batch + 1u];
    }
    let tx = lid.x;
    let ty = lid.y;
    let k_begin = slice * k_per_slice;
    let k_end = min(k, k_begin + k_per_slice);

    c0 = vec4<f32>(0.0);
    c1 = vec4<f32>(0.0);
    c2 = vec4<f32>(0.0);
    c3 = vec4<f32>(0.0);
    c4 = vec4<f32>(0.0);
    c5 = vec4<f32>(0.0);
    c6 = vec4<f32>(0.0);
    c7 = vec4<f32>(0.0);
    for (var k0 = k_begin; k0 < k_end; k0 += TILE_K) {
        // Cooperative loads, LOADS_A and LOADS_B values per thread; consecutive threads read
        // consecutive addresses of the stored matrix, whichever way it is stored.
        for (var t = 0u; t < LOADS_A; t++) {
            let e = li + 256u * t;
            var r: u32;
            var kk: u32;
            if ta {
                // A^T stored as [k, m]: along a row of the stored matrix is along m.
                r = e % TILE_M;
                kk = e / TILE_M;
            } else {
                kk = e % TILE_K;
                r = e / TILE_K;
            }
            let gr = row0 + r;
            let gk = k0 + kk;
            var v = 0.0;
            if gr < m && gk < k_end {
                if ta {
                    v = a[a_off + gk * m + gr];
                } else {
                    v = a[a_off + gr * k + gk];
                }
            }
            tile_a[kk * ROW_VEC4_A + r / 4u][r % 4u] = v;
        }
        for (var t = 0u; t < LOADS_B; t++) {
            let e = li + 256u * t;
            var c: u32;
            var kk: u32;
            if tb {
                // B^T stored as [n, k]: along a row of the stored matrix is along k.
                kk = e % TILE_K;
                c = e / TILE_K;
            } else {
                c = e % TILE_N;
                kk = e / TILE_N;
            }
            let gc = col0 + c;
            let gk = k0 + kk;
            var v = 0.0;
            if gc < n && gk < k_end {
                if tb {
                    v = b[b_off + gc * p[15] + gk];
                } else {
                    v = b[b_off + gk * p[15] + gc];
                }
            }
            tile_b[kk * ROW_VEC4_B + c / 4u][c % 4u] = v;
        }
        workgroupBarrier();
        // Only the k that exist: no additions of padding zeros.
        if k0 + TILE_K <= k_end {
            for (var kk = 0u; kk < TILE_K; kk++) {
                mac(kk, tx, ty);
            }
        } else {
            for (var kk = 0u; kk < k_end - k0; kk++) {
                mac(kk, tx, ty);
            }
        }
        workgroupBarrier();
    }

    // A slice of a split product writes its partial sums bare; otherwise the epilogue.
    let split = slices > 1u;
    let accumulate = p[5] != 0u && !split;
    let has_bias = p[6] != 0u && !split;
    var code = p[7];
    if split {
        code = 0u;
    }
    let base = p[14] + (slice * batches + batch) * m * n;
    let r = row0 + MICRO_M * ty;
    let c = col0 + 4u * tx;
    if r < m { store_row(r, c, n, base, c0, accumulate, has_bias, code); }
    if r + 1u < m { store_row(r + 1u, c, n, base, c1, accumulate, has_bias, code); }
    if r + 2u < m { store_row(r + 2u, c, n, base, c2, accumulate, has_bias, code); }
    if r + 3u < m { store_row(r + 3u, c, n, base, c3, accumulate, has_bias, code); }
    if MICRO_M == 8u {
        if r + 4u < m { store_row(r + 4u, c, n, base, c4, accumulate, has_bias, code); }
        if r + 5u < m { store_row(r + 5u, c, n, base, c5, accumulate, has_bias, code); }
        if r + 6u < m { store_row(r + 6u, c, n, base, c6, accumulate, has_bias, code); }
        if r + 7u < m { store_row(r + 7u, c, n, base, c7, accumulate, has_bias, code); }
    }
}
