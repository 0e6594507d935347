// out[i] = 1 where x[i] is NaN or an infinity (all exponent bits set), else 0. p = [n].
@group(0) @binding(1) var<storage, read> x: array<u32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = linear_id(wg, nwg, li);
    if i >= p[0] { return; }
    out[i] = select(0.0, 1.0, (x[i] & 0x7f800000u) == 0x7f800000u);
}
