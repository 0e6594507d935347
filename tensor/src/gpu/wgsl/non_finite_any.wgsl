// flags[p[1]] becomes 1.0 (its bits set with an atomic or) when any x[i], i < p[0], is NaN or
// an infinity (all exponent bits set); it is left as it was otherwise. p = [n, slot]. The
// caller clears the flags first; a flag is exact whatever order the threads run in (an or),
// and finite tensors, the usual case, make no atomic operation at all.
@group(0) @binding(1) var<storage, read> x: array<u32>;
@group(0) @binding(2) var<storage, read_write> flags: array<atomic<u32>>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = linear_id(wg, nwg, li);
    if i >= p[0] { return; }
    if (x[i] & 0x7f800000u) == 0x7f800000u {
        atomicOr(&flags[p[1]], 0x3f800000u);
    }
}
