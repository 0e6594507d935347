// Both gradients of out = op(a, b) in one launch, over the broadcast shape (the caller sums
// each back to its operand's shape). The rules of kernels/elementwise.rs's binary_backward,
// in the order dispatch.rs's tensor arithmetic evaluated them before, so the bits are those:
//   mul: ga = g b, gb = g a;   div: ga = g / b, gb = -((g y) / b);
//   minimum (maximum): with m = (a <= b) (a >= b) as 0/1, ga = g m, gb = g - g m.
// p = [n, code (2 mul, 3 div, 4 minimum, 5 maximum), want a, want b, rank, dims..,
//      strides a.., strides b..] (strided_fns.wgsl); g and y are contiguous over the shape.
// An unwanted gradient's binding is a one-element placeholder that is never written.
@group(0) @binding(1) var<storage, read> g: array<f32>;
@group(0) @binding(2) var<storage, read> a: array<f32>;
@group(0) @binding(3) var<storage, read> b: array<f32>;
@group(0) @binding(4) var<storage, read> y: array<f32>;
@group(0) @binding(5) var<storage, read_write> ga: array<f32>;
@group(0) @binding(6) var<storage, read_write> gb: array<f32>;

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = linear_id(wg, nwg, li);
    if i >= p[0] { return; }
    let gv = g[i];
    let av = a[strided_offset(i, 4u, 0u)];
    let bv = b[strided_offset(i, 4u, 1u)];
    var da: f32;
    var db: f32;
    switch p[1] {
        case 2u: { da = gv * bv; db = gv * av; }
        case 3u: { da = gv / bv; db = -((gv * y[i]) / bv); }
        case 4u: { da = gv * select(0.0, 1.0, av <= bv); db = gv - da; }
        default: { da = gv * select(0.0, 1.0, av >= bv); db = gv - da; }
    }
    if p[2] != 0u { ga[i] = da; }
    if p[3] != 0u { gb[i] = db; }
}
