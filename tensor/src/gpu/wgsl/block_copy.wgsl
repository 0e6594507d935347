// Copies (or adds) `len` entries of an axis between two tensors that agree on the other
// dims: dst[o, dst_start + k, i] (+)= src[o, src_start + k, i] for k < len.
// p = [outer, len, inner, src_n, src_start, dst_n, dst_start, accumulate].
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    let len = p[1];
    let inner = p[2];
    if t >= p[0] * len * inner { return; }
    let i = t % inner;
    let k = (t / inner) % len;
    let o = t / (inner * len);
    let s = src[(o * p[3] + p[4] + k) * inner + i];
    let d = (o * p[5] + p[6] + k) * inner + i;
    if p[7] != 0u {
        dst[d] = dst[d] + s;
    } else {
        dst[d] = s;
    }
}
