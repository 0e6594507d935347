// Gradient of norm_last: dx[r, k] = (g[r] / y[r]) * x[r, k], one thread per element.
// p = [total = rows * n, n].
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read> y: array<f32>;
@group(0) @binding(3) var<storage, read> g: array<f32>;
@group(0) @binding(4) var<storage, read_write> dx: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let t = linear_id(wg, nwg, li);
    if t >= p[0] { return; }
    let r = t / p[1];
    dx[t] = (g[r] / y[r]) * x[t];
}
