// out = mask ? a : b with broadcasting. p = [n, rank, dims.., strides a.., strides b..].
@group(0) @binding(1) var<storage, read> mask: array<u32>;
@group(0) @binding(2) var<storage, read> a: array<f32>;
@group(0) @binding(3) var<storage, read> b: array<f32>;
@group(0) @binding(4) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = linear_id(wg, nwg, li);
    if i >= p[0] { return; }
    if mask[i] != 0u {
        out[i] = a[strided_offset(i, 1u, 0u)];
    } else {
        out[i] = b[strided_offset(i, 1u, 1u)];
    }
}
