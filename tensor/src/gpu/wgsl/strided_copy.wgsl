// out[i] = scale * x[offset + strided(i)]: permute, expand, narrow and broadcasts.
// p = [n, offset, scale bits, rank, dims.., strides x..].
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = linear_id(wg, nwg, li);
    if i >= p[0] { return; }
    out[i] = pf(2u) * x[p[1] + strided_offset(i, 3u, 0u)];
}
