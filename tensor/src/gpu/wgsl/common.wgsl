// Shared by every kernel (prepended to each module by the Rust wrappers).
// Binding 0: the u32 parameters of the launch (sizes; f32 constants as bits).
@group(0) @binding(0) var<storage, read> p: array<u32>;

// The linear thread index of a one-dimensional launch of 256-thread workgroups laid out on
// an (x, y) grid (dispatches are split when they need more than 65535 workgroups).
fn linear_id(wg: vec3<u32>, nwg: vec3<u32>, li: u32) -> u32 {
    return (wg.x + wg.y * nwg.x) * 256u + li;
}

// An f32 parameter passed as its bits.
fn pf(i: u32) -> f32 {
    return bitcast<f32>(p[i]);
}
