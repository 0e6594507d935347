// out[b] (+)= op(A_b) @ op(B_b) for each batch entry b, then optionally + bias and an
// activation (ops/matmul.rs). op(A) is m x k (`a` holds A, or A^T when ta), op(B) is k x n
// (likewise with tb), all row-major; the output is [batches, m, n].
//
// p = [m, k, n, ta, tb, accumulate, has_bias, act (0 identity, 1 relu, 2 tanh), tiles_n,
//      tiles_per_batch, batches]
//
// Tiling: a workgroup of 16 x 16 threads computes a 64 x 64 tile of one batch entry's output,
// each thread a 4 x 4 micro-tile (rows 4*ty.., columns 4*tx..). The inner dim goes in steps of
// 16: the workgroup loads the 64 x 16 block of op(A) and the 16 x 64 block of op(B) into
// workgroup memory (4 values of each per thread, out-of-range ones as 0), then each thread
// adds the products of that step. Every output element is summed by one thread over k in
// increasing order (no atomics, no split of k), so the result has the same bits on every run.
//
// The workgroups are numbered linearly (wg.x + wg.y * num_workgroups.x, see Gpu::launch): the
// batch entry, then the tile row, then the tile column.
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
// (offset of A_b, offset of B_b) in elements, per batch entry (MatMulPlan::offsets).
@group(0) @binding(3) var<storage, read> offsets: array<u32>;
// [n] values added to every row when has_bias (any buffer otherwise: never read).
@group(0) @binding(4) var<storage, read> bias: array<f32>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;

const TILE_M: u32 = 64u;
const TILE_N: u32 = 64u;
const TILE_K: u32 = 16u;
// vec4s per k-row of a workgroup tile: 16 hold the 64 values, 1 of padding spreads the
// stores of the cooperative loads over the memory banks.
const ROW_VEC4: u32 = 17u;

// tile_a[kk * ROW_VEC4 + r / 4][r % 4] = op(A)[row0 + r, k0 + kk]
var<workgroup> tile_a: array<vec4<f32>, 272>;
// tile_b[kk * ROW_VEC4 + c / 4][c % 4] = op(B)[k0 + kk, col0 + c]
var<workgroup> tile_b: array<vec4<f32>, 272>;

fn activation(code: u32, v: f32) -> f32 {
    switch code {
        case 1u: { return max(v, 0.0); }
        case 2u: {
            // tanh through exp(-2|v|) <= 1: no overflow for large |v| (as unary_fns.wgsl).
            let e = exp(-2.0 * abs(v));
            return sign(v) * (1.0 - e) / (1.0 + e);
        }
        default: { return v; }
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
    let tiles_n = p[8];
    let per_batch = p[9];
    let wid = wg.x + wg.y * nwg.x;
    // The grid may hold a few more workgroups than tiles (Gpu::launch rounds up to a
    // rectangle); the test is the same for the whole workgroup.
    if wid >= per_batch * p[10] {
        return;
    }
    let batch = wid / per_batch;
    let tile = wid % per_batch;
    let row0 = (tile / tiles_n) * TILE_M;
    let col0 = (tile % tiles_n) * TILE_N;
    let a_off = offsets[2u * batch];
    let b_off = offsets[2u * batch + 1u];
    let tx = lid.x;
    let ty = lid.y;

    // acc[i][j] = output (row0 + 4 ty + i, col0 + 4 tx + j)
    var acc: array<vec4<f32>, 4>;
    for (var k0 = 0u; k0 < k; k0 += TILE_K) {
        // Cooperative loads, 4 values of each block per thread; consecutive threads read
        // consecutive addresses of the stored matrix, whichever way it is stored.
        for (var t = 0u; t < 4u; t++) {
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
            if gr < m && gk < k {
                if ta {
                    v = a[a_off + gk * m + gr];
                } else {
                    v = a[a_off + gr * k + gk];
                }
            }
            tile_a[kk * ROW_VEC4 + r / 4u][r % 4u] = v;
        }
        for (var t = 0u; t < 4u; t++) {
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
            if gc < n && gk < k {
                if tb {
                    v = b[b_off + gc * k + gk];
                } else {
                    v = b[b_off + gk * n + gc];
                }
            }
            tile_b[kk * ROW_VEC4 + c / 4u][c % 4u] = v;
        }
        workgroupBarrier();
        // Only the k that exist: no additions of padding zeros.
        let steps = min(TILE_K, k - k0);
        for (var kk = 0u; kk < steps; kk++) {
            let av = tile_a[kk * ROW_VEC4 + ty];
            let bv = tile_b[kk * ROW_VEC4 + tx];
            acc[0] = fma(vec4<f32>(av.x), bv, acc[0]);
            acc[1] = fma(vec4<f32>(av.y), bv, acc[1]);
            acc[2] = fma(vec4<f32>(av.z), bv, acc[2]);
            acc[3] = fma(vec4<f32>(av.w), bv, acc[3]);
        }
        workgroupBarrier();
    }

    // Epilogue: (+ the current value) + bias, activation; one store per element.
    let accumulate = p[5] != 0u;
    let has_bias = p[6] != 0u;
    let code = p[7];
    let base = batch * m * n;
    for (var i = 0u; i < 4u; i++) {
        let r = row0 + 4u * ty + i;
        if r >= m {
            break;
        }
        for (var j = 0u; j < 4u; j++) {
            let c = col0 + 4u * tx + j;
            if c >= n {
                break;
            }
            let idx = base + r * n + c;
            var v = acc[i][j];
            if accumulate {
                v = out[idx] + v;
            }
            if has_bias {
                v = v + bias[c];
            }
            out[idx] = activation(code, v);
        }
    }
}
