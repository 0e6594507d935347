// dx[r, i] = g[seg[r], i], times scale[seg[r]] (1 / count, from the host) when p[2] != 0.
// p = [total = rows * inner, inner, mean].
@group(0) @binding(1) var<storage, read> g: array<f32>;
@group(0) @binding(2) var<storage, read> seg: array<u32>;
@group(0) @binding(3) var<storage, read> scale: array<f32>;
@group(0) @binding(4) var<storage, read_write> dx: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    if t >= p[0] { return; }
    let inner = p[1];
    let s = seg[t / inner];
    var v = g[s * inner + t % inner];
    if p[2] != 0u {
        v *= scale[s];
    }
    dx[t] = v;
}
