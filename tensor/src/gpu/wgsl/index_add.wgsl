// dst[o, dests[q], i] += src[o, srcs[s], i] for s in offs[q]..offs[q + 1], in that order,
// starting from dst's value (index_add along an axis split as (outer, n, inner); the host's
// CSR lists each destination row's source rows in increasing order, as the CPU adds them).
// One thread per (o, q, i); the destinations are distinct, so no two threads share an output.
// p = [total = outer * nd * inner, n, m, inner, nd].
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> dests: array<u32>;
@group(0) @binding(3) var<storage, read> offs: array<u32>;
@group(0) @binding(4) var<storage, read> srcs: array<u32>;
@group(0) @binding(5) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    if t >= p[0] { return; }
    let n = p[1];
    let m = p[2];
    let inner = p[3];
    let nd = p[4];
    let i = t % inner;
    let oq = t / inner;
    let q = oq % nd;
    let o = oq / nd;
    let d = (o * n + dests[q]) * inner + i;
    var acc = dst[d];
    let end = offs[q + 1u];
    for (var s = offs[q]; s < end; s++) {
        acc += src[(o * m + srcs[s]) * inner + i];
    }
    dst[d] = acc;
}
