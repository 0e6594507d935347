// out[s, i] = sum of x[r, i] over the rows r in offs[s]..offs[s + 1] (sorted segment ids), in
// increasing r from 0.0 as the CPU adds them, times scale[s] when p[2] != 0 (means; the host
// computes 1 / count as the CPU does, and an empty segment stays 0).
// p = [total = num_segments * inner, inner, mean].
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read> offs: array<u32>;
@group(0) @binding(3) var<storage, read> scale: array<f32>;
@group(0) @binding(4) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    if t >= p[0] { return; }
    let inner = p[1];
    let s = t / inner;
    let i = t % inner;
    let start = offs[s];
    let end = offs[s + 1u];
    var acc = 0.0;
    for (var r = start; r < end; r++) {
        acc += x[r * inner + i];
    }
    if p[2] != 0u && end > start {
        acc *= scale[s];
    }
    out[t] = acc;
}
