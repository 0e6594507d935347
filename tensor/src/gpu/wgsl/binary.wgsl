// out = op(a, b) with broadcasting through strides (BinaryOp codes in ops/elementwise.rs).
// p = [n, code, offset a, offset b, rank, dims.., strides a.., strides b..] (strided_fns).
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;

fn apply(code: u32, x: f32, y: f32) -> f32 {
    switch code {
        case 0u: { return x + y; }
        case 1u: { return x - y; }
        case 2u: { return x * y; }
        case 3u: { return x / y; }
        case 4u: { return select(y, x, x <= y); }
        default: { return select(y, x, x >= y); }
    }
}

@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) li: u32) {
    let i = linear_id(wg, nwg, li);
    if i >= p[0] { return; }
    let x = a[p[2] + strided_offset(i, 4u, 0u)];
    let y = b[p[3] + strided_offset(i, 4u, 1u)];
    out[i] = apply(p[1], x, y);
}
