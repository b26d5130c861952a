//! Named arrays in safetensors files (the data sets' storage): a documented, compact format that
//! numpy/torch (`safetensors.numpy.load_file`) and burn read directly and that can be
//! memory-mapped. Files are written atomically.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;

use clothsr_geometry::error::{Error, Result};

/// Arrays to write, by name (little-endian, C order).
#[derive(Debug, Default, Clone)]
pub struct TensorWriter {
    tensors: BTreeMap<String, (Dtype, Vec<usize>, Vec<u8>)>,
    metadata: HashMap<String, String>,
}

impl TensorWriter {
    /// An empty file.
    pub fn new() -> TensorWriter {
        TensorWriter::default()
    }

    fn add(&mut self, name: &str, dtype: Dtype, shape: &[usize], bytes: Vec<u8>) -> &mut Self {
        self.tensors
            .insert(name.to_string(), (dtype, shape.to_vec(), bytes));
        self
    }

    /// An f32 array of `shape` (C order).
    pub fn f32(&mut self, name: &str, shape: &[usize], data: &[f32]) -> &mut Self {
        debug_assert_eq!(shape.iter().product::<usize>(), data.len());
        let bytes = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.add(name, Dtype::F32, shape, bytes)
    }

    /// An f64 array of `shape`.
    pub fn f64(&mut self, name: &str, shape: &[usize], data: &[f64]) -> &mut Self {
        debug_assert_eq!(shape.iter().product::<usize>(), data.len());
        let bytes = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.add(name, Dtype::F64, shape, bytes)
    }

    /// A u32 array of `shape`.
    pub fn u32(&mut self, name: &str, shape: &[usize], data: &[u32]) -> &mut Self {
        debug_assert_eq!(shape.iter().product::<usize>(), data.len());
        let bytes = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.add(name, Dtype::U32, shape, bytes)
    }

    /// Every array and metadata entry of `r`, to change some (an array written again under
    /// its name replaces it) and write the file anew.
    pub fn from_reader(r: &TensorReader) -> Result<TensorWriter> {
        let st = SafeTensors::deserialize(&r.bytes)
            .map_err(|e| Error::bad_input(&r.path, e.to_string()))?;
        let mut w = TensorWriter::new();
        for (name, v) in st.tensors() {
            w.add(&name, v.dtype(), v.shape(), v.data().to_vec());
        }
        if let Ok((_, m)) = SafeTensors::read_metadata(&r.bytes) {
            if let Some(m) = m.metadata() {
                w.metadata = m.clone();
            }
        }
        Ok(w)
    }

    /// A string in the file's metadata.
    pub fn meta(&mut self, key: &str, value: &str) -> &mut Self {
        self.metadata.insert(key.to_string(), value.to_string());
        self
    }

    /// Writes the file atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        let views: Vec<(String, TensorView<'_>)> = self
            .tensors
            .iter()
            .map(|(n, (d, s, b))| {
                TensorView::new(*d, s.clone(), b)
                    .map(|v| (n.clone(), v))
                    .map_err(|e| Error::Invalid(format!("tensor '{n}': {e}")))
            })
            .collect::<Result<_>>()?;
        let meta = (!self.metadata.is_empty()).then(|| self.metadata.clone());
        let bytes = safetensors::serialize(views, meta)
            .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
        super::write_atomic(path, &bytes)
    }
}

/// A safetensors file read into memory.
#[derive(Debug)]
pub struct TensorReader {
    path: PathBuf,
    bytes: Vec<u8>,
}

impl TensorReader {
    /// Reads `path`, checking its header.
    pub fn open(path: &Path) -> Result<TensorReader> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        TensorReader::from_bytes(bytes, path)
    }

    /// The tensors file whose content is `bytes` (errors name `path`), its header checked.
    pub fn from_bytes(bytes: Vec<u8>, path: &Path) -> Result<TensorReader> {
        SafeTensors::deserialize(&bytes)
            .map_err(|e| Error::bad_input(path, format!("not a safetensors file: {e}")))?;
        Ok(TensorReader {
            path: path.to_path_buf(),
            bytes,
        })
    }

    fn view(&self, name: &str, dtype: Dtype) -> Result<(Vec<usize>, &[u8])> {
        let st = SafeTensors::deserialize(&self.bytes)
            .map_err(|e| Error::bad_input(&self.path, e.to_string()))?;
        let v = st
            .tensor(name)
            .map_err(|_| Error::bad_input(&self.path, format!("no tensor '{name}'")))?;
        if v.dtype() != dtype {
            return Err(Error::bad_input(
                &self.path,
                format!("tensor '{name}' is {:?}, expected {dtype:?}", v.dtype()),
            ));
        }
        Ok((v.shape().to_vec(), v.data()))
    }

    /// The first value of the f64 array `name` (a scalar stored as a one-element array).
    pub fn scalar_f64(&self, name: &str) -> Result<f64> {
        self.f64(name)?
            .1
            .first()
            .copied()
            .ok_or_else(|| Error::bad_input(&self.path, format!("tensor '{name}' is empty")))
    }

    /// Whether the file holds an array named `name` (of any type).
    pub fn has(&self, name: &str) -> bool {
        SafeTensors::deserialize(&self.bytes).is_ok_and(|st| st.tensor(name).is_ok())
    }

    /// A metadata entry of the header.
    pub fn meta(&self, key: &str) -> Option<String> {
        let (_, m) = SafeTensors::read_metadata(&self.bytes).ok()?;
        m.metadata().as_ref()?.get(key).cloned()
    }

    /// An f32 array and its shape.
    pub fn f32(&self, name: &str) -> Result<(Vec<usize>, Vec<f32>)> {
        let (s, b) = self.view(name, Dtype::F32)?;
        Ok((
            s,
            b.chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        ))
    }

    /// An f64 array and its shape.
    pub fn f64(&self, name: &str) -> Result<(Vec<usize>, Vec<f64>)> {
        let (s, b) = self.view(name, Dtype::F64)?;
        Ok((
            s,
            b.chunks_exact(8)
                .map(|c| f64::from_le_bytes(std::array::from_fn(|k| c[k])))
                .collect(),
        ))
    }

    /// A u32 array and its shape.
    pub fn u32(&self, name: &str) -> Result<(Vec<usize>, Vec<u32>)> {
        let (s, b) = self.view(name, Dtype::U32)?;
        Ok((
            s,
            b.chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_round_trip_and_wrong_types_are_named() {
        let dir = tempfile::tempdir().expect("tmp");
        let p = dir.path().join("a.safetensors");
        let mut w = TensorWriter::new();
        w.f32("x", &[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, -6.5])
            .f64("y", &[1], &[std::f64::consts::PI])
            .u32("t", &[1, 3], &[0, 1, 2])
            .meta("k", "v");
        w.write(&p).expect("write");
        let r = TensorReader::open(&p).expect("open");
        assert_eq!(
            r.f32("x").expect("x"),
            (vec![2, 3], vec![1.0, 2.0, 3.0, 4.0, 5.0, -6.5])
        );
        assert_eq!(r.f64("y").expect("y").1, vec![std::f64::consts::PI]);
        assert_eq!(r.u32("t").expect("t").1, vec![0, 1, 2]);
        let e = r.f64("x").expect_err("wrong dtype").to_string();
        assert!(e.contains("a.safetensors") && e.contains("'x'"), "{e}");
        assert!(r.f32("missing").is_err());
        std::fs::write(&p, b"garbage").expect("overwrite");
        let e = TensorReader::open(&p).expect_err("garbage").to_string();
        assert!(e.contains("not a safetensors file"), "{e}");
    }
}
