// Batched products of small matrices (ops/matmul.rs chooses it when each batch entry's
// output is at most a quarter of matmul.wgsl's 64 x 64 tile and k is short: the Gram
// matrices, vector mixings and frames of the subequivariant layers, [B, 3, 32] x [B, 32, 32]
// and the like). One thread per output element sums over k in increasing order with the
// same fused multiply-adds as matmul.wgsl, so the two kernels give the same bits.
//
// p = [m, k, n, ta, tb, accumulate, has_bias, act, batches, a_base, b_base, a_stride,
//      b_stride, offsets_listed, out_base, ldb, ldo, bias_base]: batch entry b's matrices
//      start at `offsets` (when listed) or at base + b * stride, the output at out_base; the
//      stored rows of B are ldb apart and the output's ldo (matmul.wgsl), the bias starts at
//      bias_base.
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
@group(0) @binding(3) var<storage, read> offsets: array<u32>;
@group(0) @binding(4) var<storage, read> bias: array<f32>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let id = linear_id(wg, nwg, li);
    let m = p[0];
    let k = p[1];
    let n = p[2];
    let ta = p[3] != 0u;
    let tb = p[4] != 0u;
    let mn = m * n;
    if id >= mn * p[8] {
        return;
    }
    let batch = id / mn;
    let i = (id % mn) / n;
    let j = id % n;
    var a_off = p[9] + batch * p[11];
    var b_off = p[10] + batch * p[12];
    if p[13] != 0u {
        a_off = offsets[2u * batch];
        b_off = offsets[2u * batch + 1u];
    }
    var acc = 0.0;
    for (var kk = 0u; kk < k; kk++) {
        var av: f32;
        var bv: f32;
        if ta { av = a[a_off + kk * m + i]; } else { av = a[a_off + i * k + kk]; }
        if tb { bv = b[b_off + j * p[15] + kk]; } else { bv = b[b_off + kk * p[15] + j]; }
        acc = fma(av, bv, acc);
    }
    var v = acc;
    let o = p[14] + batch * mn + i * p[16] + j;
    if p[5] != 0u {
        v = out[o] + v;
    }
    if p[6] != 0u {
        v = v + bias[p[17] + j];
    }
    out[o] = activation(p[7], v);
}
