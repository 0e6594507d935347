// Strided indexing for up to 8 dims: the output index i (row-major over shape `dims`) mapped
// to an offset in an operand through its strides (0 along broadcast dims).
// Layout in p: p[base] = rank, then rank dims, then one block of rank strides per operand.

fn strided_offset(i: u32, base: u32, operand: u32) -> u32 {
    let rank = p[base];
    var rest = i;
    var off = 0u;
    for (var d = i32(rank) - 1; d >= 0; d = d - 1) {
        let dim = p[base + 1u + u32(d)];
        let idx = rest % dim;
        rest = rest / dim;
        off = off + idx * p[base + 1u + rank * (1u + operand) + u32(d)];
    }
    return off;
}
