// The second pass of a split-k product (matmul.wgsl): out[o] = act((out[o] if accumulate) +
// sum over s of part[s * total + i], in increasing s, + bias[bias_base + i % n]) with
// o = out_base + (i / n) * ldo + i % n, one thread per output element.
//
// p = [total (batches * m * n), n, slices, accumulate, has_bias, act, out_base, ldo,
//      bias_base]
@group(0) @binding(1) var<storage, read> part: array<f32>;
@group(0) @binding(2) var<storage, read> bias: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = linear_id(wg, nwg, li);
    let total = p[0];
    if i >= total {
        return;
    }
    var v = part[i];
    for (var s = 1u; s < p[2]; s++) {
        v = v + part[s * total + i];
    }
    let o = p[6] + (i / p[1]) * p[7] + i % p[1];
    if p[3] != 0u {
        v = out[o] + v;
    }
    if p[4] != 0u {
        v = v + bias[p[8] + i % p[1]];
    }
    out[o] = activation(p[5], v);
}
