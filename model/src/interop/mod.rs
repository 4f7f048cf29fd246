//! Parameters in and out of safetensors files, under any4d's own names or under the names and layouts of
//! AnimateAnyMesh's PyTorch modules (docs/method.md §12), so that a network trained here opens there and back.
//!
//! The three networks with a PyTorch counterpart map tensor for tensor (docs/method.md §12 lists the rules):
//! [`Network::Mmdit`] ↔ `DyMeshMMDiT` without its CLIP tower, [`Network::FrameVae`] ↔ the modules of a `DyMeshVAE`
//! built at the frame-wise sizes (`T = 1`, offset input 3), [`Network::DyMeshVae`] ↔ `DyMeshVAE`. Under
//! [`Names::AnimateAnyMesh`] a Linear weight is stored `[out, in]` (PyTorch's layout, burn keeps `[in, out]`), a
//! LayerNorm's `gamma`/`beta` are `weight`/`bias`, every name is renamed by [`aam_rules`], and a VAE file also holds
//! the two constant buffers AAM's `state_dict` carries (`point_embed.basis`, `traj_embed.freq_bands`), so that
//! `load_state_dict(strict=True)` accepts it. Under [`Names::Any4d`] the file holds burn's own paths and layouts.
//!
//! Reading checks the whole file before anything is applied: its header (length, JSON, offsets) by the
//! `safetensors` crate, then every tensor the network needs present, of a float dtype and of the network's shape,
//! and no other tensor (AAM's buffers and CLIP keys excepted); each refusal names the file and the tensor.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fmt;
use std::path::{Path, PathBuf};

use burn::store::burn_pack::Tensor as PackTensor;
use burn::store::{BurnToPyTorchAdapter, ModuleAdapter, ModuleSnapshot, PyTorchToBurnAdapter};
use burn::tensor::{DType, TensorData};
use regex::Regex;
use safetensors::{Dtype, SafeTensors};

mod aam;

use aam::aam_extra;
pub use aam::{aam_rules, aam_vae_buffers};

/// Metadata key naming the network a file holds ([`Network::name`]).
pub const META_NETWORK: &str = "any4d.network";
/// Metadata key naming the convention of the file's names ([`Names::name`]).
pub const META_NAMES: &str = "any4d.names";

/// Largest safetensors file read: far above the paper-size RF (313 MB in f32).
pub const MAX_FILE_BYTES: u64 = 8 << 30;

/// A network that has a counterpart in AnimateAnyMesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Network {
    /// The rectified-flow MMDiT (docs/method.md §4.3) ↔ `DyMeshMMDiT`.
    Mmdit,
    /// The frame-wise VAE (docs/method.md §3.2) ↔ `DyMeshVAE`'s modules at frame-wise sizes.
    FrameVae,
    /// The sequence-wise DyMeshVAE (docs/method.md §3.5) ↔ `DyMeshVAE`.
    DyMeshVae,
}

impl Network {
    pub fn name(self) -> &'static str {
        match self {
            Network::Mmdit => "mmdit",
            Network::FrameVae => "frame_vae",
            Network::DyMeshVae => "dymesh_vae",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        [Network::Mmdit, Network::FrameVae, Network::DyMeshVae]
            .into_iter()
            .find(|n| n.name() == name)
    }
}

/// Which names (and layouts) a file uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Names {
    /// burn's module paths and layouts (Linear `[in, out]`, LayerNorm `gamma`/`beta`).
    Any4d,
    /// AnimateAnyMesh's `state_dict` keys and PyTorch's layouts.
    AnimateAnyMesh,
}

impl Names {
    pub fn name(self) -> &'static str {
        match self {
            Names::Any4d => "any4d",
            Names::AnimateAnyMesh => "animateanymesh",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        [Names::Any4d, Names::AnimateAnyMesh]
            .into_iter()
            .find(|n| n.name() == name)
    }
}

/// Why a safetensors file could not be written or read.
#[derive(Debug)]
pub struct InteropError {
    pub path: PathBuf,
    /// The tensor (or header field) at fault; empty when the whole file is.
    pub tensor: String,
    pub reason: String,
}

impl InteropError {
    /// What went wrong, without the file: `tensor "name": reason`, or the reason alone.
    pub fn what(&self) -> String {
        match self.tensor.is_empty() {
            true => self.reason.clone(),
            false => format!("tensor {:?}: {}", self.tensor, self.reason),
        }
    }
}

impl fmt::Display for InteropError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.what())
    }
}

impl std::error::Error for InteropError {}

fn err(path: &Path, tensor: impl Into<String>, reason: impl Into<String>) -> InteropError {
    InteropError {
        path: path.to_path_buf(),
        tensor: tensor.into(),
        reason: reason.into(),
    }
}

/// One tensor as it goes into a file: its name there, shape and f32 values (little-endian bytes).
pub struct FileTensor {
    pub name: String,
    pub shape: Vec<usize>,
    pub bytes: Vec<u8>,
}

/// Renames a parameter's path (after the layout's adapter: LayerNorm `weight`/`bias` under AAM's names) to its
/// name in a file under `names`.
struct Renamer(Vec<(Regex, &'static str)>);

impl Renamer {
    fn new(network: Network, names: Names) -> Self {
        Renamer(match names {
            Names::Any4d => Vec::new(),
            Names::AnimateAnyMesh => aam_rules(network)
                .iter()
                .map(|(from, to)| (Regex::new(from).expect("a valid built-in pattern"), *to))
                .collect(),
        })
    }

    fn rename(&self, path: &str) -> String {
        let mut name = path.to_owned();
        for (re, to) in &self.0 {
            name = re.replace(&name, *to).into_owned();
        }
        name
    }
}

fn adapter_to(names: Names) -> Option<Box<dyn ModuleAdapter>> {
    match names {
        Names::Any4d => None,
        Names::AnimateAnyMesh => Some(Box::new(BurnToPyTorchAdapter)),
    }
}

/// `(path after the adapter, name in the file, shape in the file's layout)` of every parameter of `module`, without
/// reading any parameter's values.
pub fn file_names<M: ModuleSnapshot>(module: &M, network: Network, names: Names) -> Vec<(String, String, Vec<usize>)> {
    let renamer = Renamer::new(network, names);
    module
        .collect(None, adapter_to(names), false)
        .into_iter()
        .map(|t| {
            let name = renamer.rename(&t.name);
            (t.name, name, t.shape.to_vec())
        })
        .collect()
}

/// The tensors of `module` under `names`, in f32, sorted by name.
pub fn collect_tensors<M: ModuleSnapshot>(module: &M, network: Network, names: Names) -> Vec<FileTensor> {
    let renamer = Renamer::new(network, names);
    let mut out: Vec<FileTensor> = module
        .collect(None, adapter_to(names), false)
        .into_iter()
        .map(|t| {
            let name = renamer.rename(&t.name);
            let shape = t.shape.to_vec();
            let dtype = t.dtype;
            // A parameter the model cannot read back is a bug in burn or here, not bad input.
            let bytes = t.into_bytes().expect("parameter bytes");
            let data = TensorData::from_bytes_vec(bytes.to_vec(), shape.clone(), dtype).convert::<f32>();
            FileTensor {
                name,
                shape,
                bytes: data.as_bytes().to_vec(),
            }
        })
        .collect();
    out.sort_by(|a, b| a.name.cmp(&b.name));
    out
}

/// Writes `tensors` (f32) and `metadata` as a safetensors file at `path`, atomically.
pub fn write_file(path: &Path, tensors: &[FileTensor], metadata: BTreeMap<String, String>) -> Result<(), InteropError> {
    let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = tensors
        .iter()
        .map(|t| {
            safetensors::tensor::TensorView::new(Dtype::F32, t.shape.clone(), &t.bytes)
                .map(|v| (t.name.clone(), v))
                .map_err(|e| err(path, &t.name, e.to_string()))
        })
        .collect::<Result<_, _>>()?;
    let metadata: HashMap<String, String> = metadata.into_iter().collect();
    let bytes = safetensors::tensor::serialize(views, Some(metadata)).map_err(|e| err(path, "", e.to_string()))?;
    any4d_data::io::write_atomic(path, &bytes).map_err(|e| err(path, "", e.to_string()))
}

/// The `__metadata__` of a safetensors file from its header alone (its tensors are not read): what an import needs
/// before it can build the network the file holds.
pub fn read_header_metadata(path: &Path) -> Result<BTreeMap<String, String>, InteropError> {
    use std::io::Read;
    let not = |why: String| err(path, "", format!("not a safetensors file: {why}"));
    let mut f = std::fs::File::open(path).map_err(|e| err(path, "", e.to_string()))?;
    let size = f.metadata().map_err(|e| err(path, "", e.to_string()))?.len();
    let mut len = [0u8; 8];
    f.read_exact(&mut len)
        .map_err(|_| not("shorter than its 8-byte header length".into()))?;
    let n = u64::from_le_bytes(len);
    // The safetensors crate's own bound on a header.
    if n > size.saturating_sub(8) || n > 100_000_000 {
        return Err(not(format!("a header of {n} bytes in a file of {size}")));
    }
    let mut header = vec![0u8; n as usize];
    f.read_exact(&mut header).map_err(|e| err(path, "", e.to_string()))?;
    let json: serde_json::Value =
        serde_json::from_slice(&header).map_err(|e| not(format!("its header is not JSON ({e})")))?;
    Ok(json
        .get("__metadata__")
        .and_then(|m| m.as_object())
        .map(|m| {
            m.iter()
                .filter_map(|(k, v)| v.as_str().map(|v| (k.clone(), v.to_owned())))
                .collect()
        })
        .unwrap_or_default())
}

/// What [`read_file`] found besides the parameters it applied.
#[derive(Debug, Default)]
pub struct ReadReport {
    /// The file's `__metadata__`.
    pub metadata: BTreeMap<String, String>,
    /// Keys ignored as AnimateAnyMesh extras (buffers, CLIP tower).
    pub ignored: Vec<String>,
}

/// One tensor read from a file: name, dtype (when a float one), the file's name for its dtype, shape,
/// little-endian bytes.
struct Entry {
    name: String,
    float: Option<DType>,
    dtype: String,
    shape: Vec<usize>,
    data: EntryData,
}

/// A tensor's bytes: read with the file (safetensors), or read on demand (a pickle's tensor, which may be a strided
/// view whose full size is only paid once its name and shape have been checked against the network's).
enum EntryData {
    Read(Vec<u8>),
    Lazy(PackTensor),
}

impl Entry {
    fn into_bytes(self) -> Result<Vec<u8>, String> {
        match self.data {
            EntryData::Read(b) => Ok(b),
            EntryData::Lazy(t) => t.into_bytes().map(|b| b.to_vec()).map_err(|e| e.to_string()),
        }
    }
}

/// Whether `path` names a PyTorch pickle (`torch.save`) rather than safetensors.
pub fn is_pytorch_pickle(path: &Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or_default()
        .to_ascii_lowercase();
    matches!(ext.as_str(), "pt" | "pth" | "ckpt")
}

fn safetensors_entries(path: &Path) -> Result<(BTreeMap<String, String>, Vec<Entry>), InteropError> {
    let bytes = any4d_data::formats::read_file(path, MAX_FILE_BYTES).map_err(|e| err(path, "", e.reason))?;
    let (_, header) =
        SafeTensors::read_metadata(&bytes).map_err(|e| err(path, "", format!("not a safetensors file: {e}")))?;
    let file = SafeTensors::deserialize(&bytes).map_err(|e| err(path, "", format!("not a safetensors file: {e}")))?;
    let mut entries = Vec::new();
    for (name, view) in file.tensors() {
        let float = match view.dtype() {
            Dtype::F32 => Some(DType::F32),
            Dtype::F16 => Some(DType::F16),
            Dtype::BF16 => Some(DType::BF16),
            Dtype::F64 => Some(DType::F64),
            _ => None,
        };
        entries.push(Entry {
            name,
            float,
            dtype: format!("{:?}", view.dtype()),
            shape: view.shape().to_vec(),
            data: EntryData::Read(view.data().to_vec()),
        });
    }
    Ok((
        header.metadata().clone().unwrap_or_default().into_iter().collect(),
        entries,
    ))
}

/// The tensors of a PyTorch pickle, read by burn's reader (which never runs the pickle's code): the file's own
/// dictionary, or its `model_state_dict` / `state_dict` entry (a training checkpoint), the `module.` prefix of a
/// data-parallel model dropped.
fn pytorch_entries(path: &Path) -> Result<Vec<Entry>, InteropError> {
    use burn::store::{ModuleStore, PytorchStore};
    let meta = std::fs::metadata(path).map_err(|e| err(path, "", e.to_string()))?;
    if !meta.is_file() || meta.len() > MAX_FILE_BYTES {
        return Err(err(
            path,
            "",
            format!("not a regular file of at most {MAX_FILE_BYTES} bytes"),
        ));
    }
    let mut last = String::new();
    // A training checkpoint's model first (its optimiser state would otherwise be read as parameters), then the
    // file's own dictionary; the error of the last try is the one that says what the file is.
    for key in [Some("model_state_dict"), Some("state_dict"), None] {
        let mut store = PytorchStore::from_file(path).map_indices_contiguous(false);
        if let Some(k) = key {
            store = store.with_top_level_key(k);
        }
        let all = match store.get_all_tensors() {
            Ok(all) if !all.is_empty() => all,
            Ok(_) => continue,
            Err(e) => {
                last = e.to_string();
                continue;
            }
        };
        let strip = all.keys().all(|k| k.starts_with("module."));
        let mut entries = Vec::with_capacity(all.len());
        for (name, t) in all {
            let name = if strip {
                name["module.".len()..].to_owned()
            } else {
                name.clone()
            };
            let float = matches!(t.dtype, DType::F32 | DType::F16 | DType::BF16 | DType::F64).then_some(t.dtype);
            // No bytes yet: a hostile pickle's stride-0 view can stand for gigabytes.
            entries.push(Entry {
                float,
                dtype: format!("{:?}", t.dtype),
                shape: t.shape.to_vec(),
                data: EntryData::Lazy(t.clone()),
                name,
            });
        }
        return Ok(entries);
    }
    Err(err(
        path,
        "",
        format!(
            "not a PyTorch state_dict burn's reader can read (a dictionary of tensors, or a checkpoint holding one under model_state_dict or state_dict): {last}"
        ),
    ))
}

/// Reads the file at `path` (safetensors, or a PyTorch pickle by its extension `.pt`/`.pth`/`.ckpt`; names under
/// `names`) into `module`, whose sizes must be the file's: every parameter present with its shape and a float dtype
/// (cast to f32), no key the network does not have (AAM's CLIP keys excepted), and AAM's constant buffers, where the
/// file has them, equal to `constants` (the module's own, [`aam_vae_buffers`]): a module built with other
/// frequencies computes another function. A tensor's bytes are read only once its name, shape and dtype have passed;
/// the module is changed only after every tensor has.
pub fn read_file<M: ModuleSnapshot>(
    module: &mut M,
    path: &Path,
    network: Network,
    names: Names,
    constants: &[(String, Vec<usize>, Vec<f32>)],
) -> Result<ReadReport, InteropError> {
    let (metadata, entries) = match is_pytorch_pickle(path) {
        true => (BTreeMap::new(), pytorch_entries(path)?),
        false => safetensors_entries(path)?,
    };
    let expected = file_names(module, network, names);
    let wanted: HashSet<&str> = expected.iter().map(|(_, name, _)| name.as_str()).collect();
    let mut report = ReadReport {
        metadata,
        ..ReadReport::default()
    };
    let mut entries = entries;
    entries.sort_unstable_by(|a, b| a.name.cmp(&b.name));
    let mut by_name: HashMap<String, Entry> = HashMap::new();
    for e in entries {
        if wanted.contains(e.name.as_str()) {
            by_name.insert(e.name.clone(), e);
            continue;
        }
        if names == Names::AnimateAnyMesh && aam_extra(network, &e.name) {
            let name = e.name.clone();
            if let Some((_, shape, values)) = constants.iter().find(|c| c.0 == name) {
                check_constant(path, e, shape, values)?;
            }
            report.ignored.push(name);
            continue;
        }
        return Err(err(
            path,
            &e.name,
            format!("not a parameter of the {} under {} names", network.name(), names.name()),
        ));
    }
    let mut tensors = Vec::with_capacity(expected.len());
    for (burn_path, name, shape) in &expected {
        let e = by_name.remove(name.as_str()).ok_or_else(|| {
            err(
                path,
                name,
                format!("missing (the {} needs it, shape {shape:?})", network.name()),
            )
        })?;
        if &e.shape != shape {
            return Err(err(
                path,
                name,
                format!("shape {:?}, the network's is {shape:?}", e.shape),
            ));
        }
        let Some(dtype) = e.float else {
            return Err(err(
                path,
                name,
                format!("dtype {}, a float parameter needs F32, F16, BF16 or F64", e.dtype),
            ));
        };
        let bytes = e.into_bytes().map_err(|why| err(path, name, why))?;
        let data = TensorData::from_bytes_vec(bytes, shape.clone(), dtype).convert::<f32>();
        tensors.push(PackTensor::new(
            burn_path.clone(),
            DType::F32,
            shape.clone(),
            None,
            data.into_bytes(),
        ));
    }
    let adapter: Option<Box<dyn ModuleAdapter>> = match names {
        Names::Any4d => None,
        Names::AnimateAnyMesh => Some(Box::new(PyTorchToBurnAdapter)),
    };
    let result = module.apply(tensors, None, adapter, false);
    if let Some(e) = result.errors.first() {
        return Err(err(path, "", format!("could not apply: {e}")));
    }
    if let Some((name, _)) = result.missing.first() {
        return Err(err(path, name, "the network's parameter was not filled"));
    }
    Ok(report)
}

/// Refuses an AnimateAnyMesh buffer whose shape or values (within 10⁻⁶ relative) are not the module's own.
fn check_constant(path: &Path, e: Entry, shape: &[usize], values: &[f32]) -> Result<(), InteropError> {
    let name = e.name.clone();
    let differs = |why: String| {
        err(
            path,
            &name,
            format!("{why}: built with other frequencies than this network"),
        )
    };
    if e.shape != shape {
        return Err(differs(format!("shape {:?}, the network's is {shape:?}", e.shape)));
    }
    let Some(dtype) = e.float else {
        return Err(differs(format!("dtype {}", e.dtype)));
    };
    let bytes = e.into_bytes().map_err(|why| err(path, &name, why))?;
    let got = TensorData::from_bytes_vec(bytes, shape.to_vec(), dtype).convert::<f32>();
    let got: Vec<f32> = got
        .try_to_vec::<f32>()
        .map_err(|why| err(path, &name, format!("{why:?}")))?;
    match got
        .iter()
        .zip(values)
        .position(|(a, b)| (a - b).abs() > 1e-6 * b.abs().max(1.0))
    {
        Some(i) => Err(differs(format!(
            "value {i} is {}, the network's is {}",
            got[i], values[i]
        ))),
        None => Ok(()),
    }
}
