//! safetensors files, the format of a checkpoint's tensors ([`crate::mappo::checkpoint`])
//! and of a policy file ([`crate::app::policy_file`]): 8 bytes of header length
//! (little-endian), a JSON header naming every tensor's dtype, shape and byte range (and a
//! `__metadata__` map of strings), then the raw little-endian data. PyTorch, JAX/Flax, candle,
//! numpy (`safetensors.numpy.load_file`) and the Hugging Face tools read it; it holds no code.
//!
//! Reading goes through the `safetensors` crate (the format's reference implementation,
//! which validates offsets, sizes and the header of an untrusted file). Writing is done here,
//! to the same layout as the crate's `serialize` (tensors sorted by decreasing dtype
//! alignment then name, the header padded with spaces to a multiple of 8 bytes), but with the
//! `__metadata__` keys in sorted order: the crate takes them as a `HashMap`, whose order
//! changes from one process to the next, and a file must be the same bytes every time it is
//! written from the same state (checkpoint tensor files are named by their digest, and a
//! policy exported twice is the same file). Tests read these files back with the crate and,
//! in Python, with the `safetensors` package.

use std::collections::BTreeMap;

pub use safetensors::{Dtype, SafeTensors};

/// One tensor to write.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// Its name in the file.
    pub name: String,
    /// Element type.
    pub dtype: Dtype,
    /// Shape.
    pub shape: Vec<usize>,
    /// Elements, little-endian, row-major.
    pub data: Vec<u8>,
}

impl Entry {
    /// An `F32` tensor.
    pub fn f32(name: impl Into<String>, shape: &[usize], values: impl IntoIterator<Item = f32>) -> Entry {
        let data = values.into_iter().flat_map(f32::to_le_bytes).collect();
        Entry { name: name.into(), dtype: Dtype::F32, shape: shape.to_vec(), data }
    }

    /// An `F64` tensor.
    pub fn f64(name: impl Into<String>, shape: &[usize], values: &[f64]) -> Entry {
        let data = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        Entry { name: name.into(), dtype: Dtype::F64, shape: shape.to_vec(), data }
    }

    /// `values` as `F32` when every one of them is an f32 value (bit for bit: the
    /// parameters of an f32 model, which a state dictionary holds as f64), else as `F64`:
    /// either way reading gives back the same f64 bits, in half the bytes for f32 models.
    pub fn exact(name: impl Into<String>, shape: &[usize], values: &[f64]) -> Entry {
        let is_f32 = |x: f64| (x as f32 as f64).to_bits() == x.to_bits();
        if values.iter().all(|&x| is_f32(x)) {
            Entry::f32(name, shape, values.iter().map(|&x| x as f32))
        } else {
            Entry::f64(name, shape, values)
        }
    }
}

/// The bytes of a safetensors file holding `entries` and `metadata` (module docs). Two
/// entries of one name are refused.
pub fn serialize(mut entries: Vec<Entry>, metadata: &BTreeMap<String, String>) -> Result<Vec<u8>, String> {
    // The crate's order: decreasing dtype (alignment), then name.
    entries.sort_by(|a, b| b.dtype.cmp(&a.dtype).then_with(|| a.name.cmp(&b.name)));
    if let Some(w) = entries.windows(2).find(|w| w[0].name == w[1].name) {
        return Err(format!("two tensors named `{}`", w[0].name));
    }
    let mut header = serde_json::Map::new();
    if !metadata.is_empty() {
        let m: serde_json::Map<String, serde_json::Value> =
            metadata.iter().map(|(k, v)| (k.clone(), serde_json::Value::String(v.clone()))).collect();
        header.insert("__metadata__".into(), serde_json::Value::Object(m));
    }
    let mut offset = 0usize;
    for e in &entries {
        let n: usize = e.shape.iter().product();
        if n * e.dtype.bitsize() != e.data.len() * 8 {
            return Err(format!(
                "tensor `{}`: {} bytes for shape {:?} of {:?}",
                e.name,
                e.data.len(),
                e.shape,
                e.dtype
            ));
        }
        let dtype = serde_json::to_value(e.dtype).map_err(|x| x.to_string())?;
        let info =
            serde_json::json!({ "dtype": dtype, "shape": e.shape, "data_offsets": [offset, offset + e.data.len()] });
        header.insert(e.name.clone(), info);
        offset += e.data.len();
    }
    let mut head = serde_json::to_vec(&header).map_err(|x| x.to_string())?;
    head.resize(head.len().next_multiple_of(8), b' ');
    let mut out = Vec::with_capacity(8 + head.len() + offset);
    out.extend_from_slice(&(head.len() as u64).to_le_bytes());
    out.extend_from_slice(&head);
    for e in &entries {
        out.extend_from_slice(&e.data);
    }
    Ok(out)
}

/// The parsed file (tensors borrowed from `bytes`) and its metadata; the error says what
/// is wrong (a truncated file, a header that is not JSON, offsets that do not fit).
pub fn read(bytes: &[u8]) -> Result<(SafeTensors<'_>, BTreeMap<String, String>), String> {
    let describe = |e: safetensors::SafeTensorError| format!("not a valid safetensors file ({e})");
    let (_, meta) = SafeTensors::read_metadata(bytes).map_err(describe)?;
    let metadata = meta.metadata().clone().unwrap_or_default().into_iter().collect();
    let tensors = SafeTensors::deserialize(bytes).map_err(describe)?;
    Ok((tensors, metadata))
}

/// Every tensor of `file` as an [`Entry`] (its name, dtype, shape and bytes), in name
/// order: what [`serialize`] takes to write the file again.
pub fn entries_of(file: &SafeTensors<'_>) -> Vec<Entry> {
    let mut entries: Vec<Entry> = file
        .tensors()
        .into_iter()
        .map(|(name, t)| Entry { name, dtype: t.dtype(), shape: t.shape().to_vec(), data: t.data().to_vec() })
        .collect();
    entries.sort_by(|a, b| a.name.cmp(&b.name));
    entries
}

/// The tensor `name` of `file` as f64 values (from `F32` or `F64`) with its shape; the
/// error names the tensor.
pub fn f64_values(file: &SafeTensors<'_>, name: &str) -> Result<(Vec<usize>, Vec<f64>), String> {
    let t = file.tensor(name).map_err(|_| format!("tensor `{name}` is missing"))?;
    let values = match t.dtype() {
        Dtype::F32 => t.data().chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64).collect(),
        Dtype::F64 => t.data().chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect(),
        d => return Err(format!("tensor `{name}` is {d:?}, expected F32 or F64")),
    };
    Ok((t.shape().to_vec(), values))
}

/// The tensor `name` of `file` as f32 values (from `F32` only: nothing is rounded) with its
/// shape; the error names the tensor.
pub fn f32_values(file: &SafeTensors<'_>, name: &str) -> Result<(Vec<usize>, Vec<f32>), String> {
    let t = file.tensor(name).map_err(|_| format!("tensor `{name}` is missing"))?;
    if t.dtype() != Dtype::F32 {
        return Err(format!("tensor `{name}` is {:?}, expected F32", t.dtype()));
    }
    Ok((t.shape().to_vec(), t.data().chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_read_back_through_the_crate_with_the_same_bits_and_bytes() {
        let meta: BTreeMap<String, String> =
            [("b", "2"), ("a", "{\"x\":1}"), ("c", "")].iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        let tiny = 1e-300;
        let entries = vec![
            Entry::exact("w", &[2, 2], &[1.5, -0.0, 3.0, f32::MAX as f64]),
            Entry::exact("m", &[3], &[0.1, tiny, -2.0]),
            Entry::f32("z", &[0], []),
        ];
        assert_eq!(entries[0].dtype, Dtype::F32);
        assert_eq!(entries[1].dtype, Dtype::F64);
        let bytes = serialize(entries.clone(), &meta).unwrap();
        assert_eq!(serialize(entries.clone(), &meta).unwrap(), bytes, "the same bytes every time");
        // The crate's own writer gives the same tensor layout.
        let ours = SafeTensors::deserialize(&bytes).unwrap();
        let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = entries
            .iter()
            .map(|e| (e.name.clone(), safetensors::tensor::TensorView::new(e.dtype, e.shape.clone(), &e.data).unwrap()))
            .collect();
        let theirs_bytes = safetensors::serialize(views, None).unwrap();
        let theirs = SafeTensors::deserialize(&theirs_bytes).unwrap();
        assert_eq!(ours.names().len(), 3);
        for name in ["w", "m", "z"] {
            assert_eq!(ours.tensor(name).unwrap(), theirs.tensor(name).unwrap(), "{name}");
        }
        let (file, m) = read(&bytes).unwrap();
        assert_eq!(m, meta);
        let (shape, w) = f64_values(&file, "w").unwrap();
        assert_eq!(shape, [2, 2]);
        assert_eq!(w[1].to_bits(), (-0.0f64).to_bits());
        assert_eq!(f64_values(&file, "m").unwrap().1, [0.1, tiny, -2.0]);
        assert!(f32_values(&file, "m").unwrap_err().contains("F64"));
        assert!(f64_values(&file, "nope").unwrap_err().contains("`nope` is missing"));
        for cut in [0, 5, 8, bytes.len() / 2, bytes.len() - 1] {
            assert!(read(&bytes[..cut]).unwrap_err().contains("not a valid safetensors file"), "{cut}");
        }
        let twice = vec![Entry::f32("a", &[1], [1.0]), Entry::f32("a", &[1], [2.0])];
        assert!(serialize(twice, &meta).unwrap_err().contains("two tensors named `a`"));
    }
}
