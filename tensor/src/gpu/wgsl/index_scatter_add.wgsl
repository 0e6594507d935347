// dst[dests[q]] += src[srcs[s]] for s in offs[q]..offs[q + 1], in that order, starting from
// dst's value (the adjoint of gather: the host's CSR lists each destination element's sources
// in increasing order, as the CPU adds them). One thread per distinct destination.
// p = [nd].
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> dests: array<u32>;
@group(0) @binding(3) var<storage, read> offs: array<u32>;
@group(0) @binding(4) var<storage, read> srcs: array<u32>;
@group(0) @binding(5) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let q = linear_id(wg, nwg, li);
    if q >= p[0] { return; }
    let d = dests[q];
    var acc = dst[d];
    let end = offs[q + 1u];
    for (var s = offs[q]; s < end; s++) {
        acc += src[srcs[s]];
    }
    dst[d] = acc;
}
