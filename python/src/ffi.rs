//! `diffsvg.jax`'s forward and backward passes as XLA FFI handlers (custom calls on the
//! CPU), so that a jitted step calls diffsvg without Python in between.
//!
//! **Why `unsafe` here** (the only module of the package that has it): XLA calls a handler
//! through its C API with raw pointers to a call frame, buffers and attributes, and the
//! handler must be an exported `extern "C"` function. The alternative,
//! `jax.pure_callback` (still the fallback where these cannot be registered), goes through
//! Python on every call (the GIL, numpy wrapping, the hand-offs between XLA's thread and
//! the Python one). Measured with `python -P python/bench_jax.py --paths 256,1096
//! --steps 30` on the loaded 2-core machine (load 4.2–7.7, six runs each, alternating),
//! the jitted step was 1.16–1.43× the numpy step at 256 paths with the callbacks and
//! 0.96–1.13× with these handlers; 0.99–1.10× and 0.94–1.00× at 1,096 paths
//! (docs/python.md, "JAX"). Every `unsafe` block reads or writes memory XLA
//! owns for the duration of the call, with the layout its C header
//! (`jaxlib/include/xla/ffi/api/c_api.h`, API 0.3) gives; only the structs read are
//! mirrored here, `#[repr(C)]`.
//!
//! The handlers (`diffsvg_ffi_render`, `diffsvg_ffi_render_backward`) are registered by
//! `diffsvg/jax.py` with `jax.ffi.register_ffi_target` (as `diffsvg_render` and
//! `diffsvg_render_backward`) from `ctypes.CDLL(_native.__file__)`. Their operands:
//!
//! * forward: params `f32` or `f64` `[batch..., n]` -> image `f32` `[batch..., h, w, 4]`;
//! * backward: params, `d_image` `f32` `[batch..., h, w, 4]` -> the gradient
//!   `[batch..., n]` in the params' dtype;
//!
//! and attributes `scene` (the id [`scene_id`] gave, `u64`), `tolerance` (`f64`) and,
//! when there is one, `background` (four `f32`, straight RGBA). `vmap` reaches the
//! handlers as the leading batch dimensions (`vmap_method="broadcast_all"`): one call, its
//! rows in parallel, exactly as `render_batch` / `render_backward_batch` (the same code,
//! [`render_rows`] and [`backward_rows`], so the same bits).
//!
//! **The scene**: a handler cannot hold a Python object, so a scene used by `diffsvg.jax`
//! is registered here, by id, as a snapshot of its topology (the rows give every value);
//! the snapshot is replaced whenever the Python scene changes (`set_params`, shapes added,
//! removed or reordered) and removed when the Python scene is dropped ([`forget`]).
//!
//! **Non-finite values**: as with the callbacks, a row holding a non-finite parameter (or
//! `d_image` value) renders as NaN (its gradient NaN), the other rows as usual, and the
//! handler takes the GIL to issue one `diffsvg.jax.DiffsvgWarning` naming the first such
//! value (the only time it touches Python). Any other failure is returned to XLA as an
//! error carrying diffsvg's one-line message.

#![allow(unsafe_code)]

use std::collections::HashMap;
use std::ffi::{CString, c_char, c_int, c_void};
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use diffsvg::Scene;
use diffsvg::raster::RenderOptions;
use diffsvg::scene::ParamLayout;
use numpy::ndarray::{Array2, ArrayView1, ArrayView4};
use pyo3::prelude::*;

use crate::batch::{backward_rows, render_rows};
use crate::scene::{PyScene, Rendered};

// ----- the registry of scenes ------------------------------------------------------------

/// What a handler needs of a scene: its topology and the cache of the rows rendered last.
struct Registered {
    scene: Scene,
    /// `ParamLayout::new(&scene).len()`.
    n: usize,
    /// `scene.params()`, computed on the first `f32` call (see [`rows_of`]).
    current: OnceLock<Vec<f64>>,
    rendered: Mutex<Vec<Rendered>>,
}

impl Registered {
    fn new(scene: &Scene) -> Self {
        Registered {
            scene: scene.clone(),
            n: ParamLayout::new(scene).len(),
            current: OnceLock::new(),
            rendered: Mutex::new(Vec::new()),
        }
    }
}

fn registry() -> std::sync::MutexGuard<'static, HashMap<u64, Arc<Registered>>> {
    static REGISTRY: OnceLock<Mutex<HashMap<u64, Arc<Registered>>>> = OnceLock::new();
    REGISTRY
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner())
}

/// The registry id of `scene` (registering it on first use): what `diffsvg.jax` passes to
/// the handlers as the `scene` attribute. Ids are never reused.
pub(crate) fn scene_id(scene: &PyScene) -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    let id = scene.ffi_id.load(Ordering::Acquire);
    if id != 0 {
        return id;
    }
    let id = NEXT.fetch_add(1, Ordering::Relaxed);
    let entry = Arc::new(Registered::new(&scene.inner)); // copied before locking
    registry().insert(id, entry);
    scene.ffi_id.store(id, Ordering::Release);
    id
}

/// After `scene` changed: its snapshot, if it has one, is replaced (a copy of the scene).
pub(crate) fn changed(scene: &PyScene) {
    let id = scene.ffi_id.load(Ordering::Acquire);
    if id != 0 {
        let entry = Arc::new(Registered::new(&scene.inner)); // copied before locking
        registry().insert(id, entry);
    }
}

/// Removes the snapshot of a dropped scene (`id` 0: none).
pub(crate) fn forget(id: u64) {
    if id != 0 {
        registry().remove(&id);
    }
}

/// Whether `id` is registered (for the tests: a dropped scene's entry goes away).
#[pyfunction]
pub(crate) fn ffi_registered(id: u64) -> bool {
    registry().contains_key(&id)
}

/// The registry id of `scene`, registering it on first use.
#[pyfunction]
pub(crate) fn ffi_scene(scene: PyRef<'_, PyScene>) -> u64 {
    scene_id(&scene)
}

// ----- the C API, the parts read (xla/ffi/api/c_api.h) ---------------------------------

const EXTENSION_METADATA: c_int = 1;
const STAGE_EXECUTE: c_int = 3;
const DTYPE_U64: c_int = 9;
const DTYPE_S64: c_int = 5;
const DTYPE_F32: c_int = 11;
const DTYPE_F64: c_int = 12;
const ATTR_ARRAY: c_int = 1;
const ATTR_SCALAR: c_int = 3;
const ARG_BUFFER: c_int = 1;
const ERROR_INVALID_ARGUMENT: c_int = 3;
const ERROR_INTERNAL: c_int = 13;

#[repr(C)]
struct ExtensionBase {
    struct_size: usize,
    kind: c_int,
    next: *mut ExtensionBase,
}

#[repr(C)]
struct ApiVersion {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    major_version: c_int,
    minor_version: c_int,
}

#[repr(C)]
struct Metadata {
    struct_size: usize,
    api_version: ApiVersion,
    traits: u32,
    state_type_id: i64,
}

#[repr(C)]
struct MetadataExtension {
    extension_base: ExtensionBase,
    metadata: *mut Metadata,
}

#[repr(C)]
struct ErrorCreateArgs {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    message: *const c_char,
    errc: c_int,
}

/// The start of `XLA_FFI_Api`: only `XLA_FFI_Error_Create` is called.
#[repr(C)]
struct Api {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    api_version: ApiVersion,
    internal_api: *const c_void,
    error_create: Option<unsafe extern "C" fn(*mut ErrorCreateArgs) -> *mut c_void>,
}

#[repr(C)]
struct Buffer {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    dtype: c_int,
    data: *mut c_void,
    rank: i64,
    dims: *const i64,
}

#[repr(C)]
struct List {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    size: i64,
    types: *const c_int,
    items: *const *mut c_void,
}

#[repr(C)]
struct ByteSpan {
    ptr: *const c_char,
    len: usize,
}

#[repr(C)]
struct Attrs {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    size: i64,
    types: *const c_int,
    names: *const *const ByteSpan,
    attrs: *const *mut c_void,
}

#[repr(C)]
struct Scalar {
    dtype: c_int,
    value: *const c_void,
}

#[repr(C)]
struct AttrArray {
    dtype: c_int,
    size: usize,
    data: *const c_void,
}

#[repr(C)]
pub struct CallFrame {
    struct_size: usize,
    extension_start: *mut ExtensionBase,
    api: *const Api,
    ctx: *mut c_void,
    stage: c_int,
    args: List,
    rets: List,
    attrs: Attrs,
}

/// `offsetof(XLA_FFI_Metadata, traits) + sizeof(traits)`: a metadata struct this large
/// has `api_version` and `traits`; one of `size_of::<Metadata>()` has `state_type_id`.
const METADATA_MIN_SIZE: usize = std::mem::offset_of!(Metadata, traits) + 4;
/// `XLA_FFI_CallFrame_STRUCT_SIZE`: the fields up to `attrs`.
const CALL_FRAME_SIZE: usize = std::mem::size_of::<CallFrame>();

/// One operand or result of a call: its dtype, dims and data. Made only by
/// [`Frame::operand`], so `data` is XLA's buffer for the call; not `Clone`, so an output's
/// values are borrowed mutably once.
struct Operand {
    dtype: c_int,
    dims: Vec<usize>,
    data: *mut c_void,
}

impl Operand {
    fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// The number of values, checking the dtype code; `None` when there is no data.
    fn count(&self, dtype: c_int) -> Result<Option<usize>, String> {
        if self.dtype != dtype {
            return Err(format!(
                "dtype code {} where {dtype} was expected",
                self.dtype
            ));
        }
        let n = self.len();
        Ok((n > 0 && !self.data.is_null()).then_some(n))
    }

    /// The values as `T` (`dtype`: `T`'s code).
    fn input<T>(&self, dtype: c_int) -> Result<&[T], String> {
        let Some(n) = self.count(dtype)? else {
            return Ok(&[]);
        };
        // SAFETY: XLA's buffer of this dtype holds `product(dims)` aligned elements of it
        // for the duration of the call (c_api.h, XLA_FFI_Buffer); an input is not written.
        Ok(unsafe { std::slice::from_raw_parts(self.data as *const T, n) })
    }

    /// The values as `T`, to write (an output).
    fn output<T>(&mut self, dtype: c_int) -> Result<&mut [T], String> {
        let Some(n) = self.count(dtype)? else {
            return Ok(&mut []);
        };
        // SAFETY: as in `input`; a result buffer is ours to write during the call, and
        // `&mut self` keeps this the only slice of it.
        Ok(unsafe { std::slice::from_raw_parts_mut(self.data as *mut T, n) })
    }
}

/// The attributes a handler reads.
struct Options {
    scene: u64,
    tolerance: f64,
    background: Option<[f32; 4]>,
    /// The optional attribute `exact_overlaps` (an integer scalar, non-zero: on).
    exact_overlaps: bool,
}

/// A call frame XLA passed to a handler: made only in [`handle`], so its pointers are
/// XLA's, valid for the call.
struct Frame<'a>(&'a CallFrame);

impl Frame<'_> {
    /// The `i`-th argument (`ret`: result) buffer.
    fn operand(&self, ret: bool, i: usize, what: &str) -> Result<Operand, String> {
        let list = if ret { &self.0.rets } else { &self.0.args };
        if i as i64 >= list.size {
            return Err(format!(
                "{what}: missing (the call has {} operands)",
                list.size
            ));
        }
        // SAFETY: `types` and `items` hold `size` entries (c_api.h, XLA_FFI_Args/Rets),
        // and `i < size`.
        let (kind, item) = unsafe { (*list.types.add(i), *list.items.add(i)) };
        if kind != ARG_BUFFER || item.is_null() {
            return Err(format!("{what}: not a buffer"));
        }
        // SAFETY: a BUFFER entry points to an `XLA_FFI_Buffer`, whose `dims` holds `rank`
        // values; both live for the call.
        let b = unsafe { &*(item as *const Buffer) };
        let rank = usize::try_from(b.rank).map_err(|_| format!("{what}: rank {}", b.rank))?;
        let dims: &[i64] = if rank == 0 {
            &[]
        } else {
            // SAFETY: as above.
            unsafe { std::slice::from_raw_parts(b.dims, rank) }
        };
        let dims = dims
            .iter()
            .map(|&d| usize::try_from(d).map_err(|_| format!("{what}: dimension {d}")))
            .collect::<Result<_, _>>()?;
        Ok(Operand {
            dtype: b.dtype,
            dims,
            data: b.data,
        })
    }

    /// The attributes of the call.
    fn options(&self) -> Result<Options, String> {
        let attrs = &self.0.attrs;
        let mut scene = None;
        let mut tolerance = None;
        let mut background = None;
        let mut exact_overlaps = false;
        for i in 0..usize::try_from(attrs.size).unwrap_or(0) {
            // SAFETY: `types`, `names` and `attrs` hold `size` entries; a name is a byte
            // span (not NUL-terminated); a SCALAR attribute points to an `XLA_FFI_Scalar`
            // and an ARRAY one to an `XLA_FFI_Array`, whose values have the dtype they
            // name (read only after checking it).
            unsafe {
                let kind = *attrs.types.add(i);
                let name = &**attrs.names.add(i);
                let name = std::slice::from_raw_parts(name.ptr as *const u8, name.len);
                let attr = *attrs.attrs.add(i);
                match (name, kind) {
                    (b"scene", ATTR_SCALAR) => {
                        let s = &*(attr as *const Scalar);
                        scene = match s.dtype {
                            DTYPE_U64 => Some(*(s.value as *const u64)),
                            DTYPE_S64 => u64::try_from(*(s.value as *const i64)).ok(),
                            _ => None,
                        };
                    }
                    (b"tolerance", ATTR_SCALAR) => {
                        let s = &*(attr as *const Scalar);
                        if s.dtype == DTYPE_F64 {
                            tolerance = Some(*(s.value as *const f64));
                        }
                    }
                    (b"exact_overlaps", ATTR_SCALAR) => {
                        let s = &*(attr as *const Scalar);
                        exact_overlaps = match s.dtype {
                            DTYPE_S64 => *(s.value as *const i64) != 0,
                            DTYPE_U64 => *(s.value as *const u64) != 0,
                            _ => false,
                        };
                    }
                    (b"background", ATTR_ARRAY) => {
                        let a = &*(attr as *const AttrArray);
                        if a.dtype == DTYPE_F32 && a.size == 4 {
                            let v = std::slice::from_raw_parts(a.data as *const f32, 4);
                            background = Some([v[0], v[1], v[2], v[3]]);
                        }
                    }
                    _ => {}
                }
            }
        }
        Ok(Options {
            scene: scene.ok_or("the attribute scene (u64) is missing")?,
            tolerance: tolerance.ok_or("the attribute tolerance (f64) is missing")?,
            background,
            exact_overlaps,
        })
    }
}

/// An XLA error carrying `msg`.
///
/// # Safety
/// `api` must be the call frame's API pointer.
unsafe fn error(api: *const Api, code: c_int, msg: &str) -> *mut c_void {
    let msg = CString::new(msg.replace('\0', " ")).expect("no NUL left");
    let mut args = ErrorCreateArgs {
        struct_size: std::mem::size_of::<ErrorCreateArgs>(),
        extension_start: std::ptr::null_mut(),
        message: msg.as_ptr(),
        errc: code,
    };
    // SAFETY: `api` is XLA's API table for this call; `XLA_FFI_Error_Create` copies the
    // message (c_api.h: the error owns its status).
    unsafe {
        match api.as_ref().and_then(|a| a.error_create) {
            Some(create) => create(&mut args),
            None => std::ptr::null_mut(),
        }
    }
}

/// The common part of both handlers: the metadata query at registration, the stages, the
/// attributes, errors; `run` does the work and returns the warning to issue, if any.
///
/// # Safety
/// `frame` must be the call frame XLA passed to the handler (or null).
unsafe fn handle(
    frame: *mut CallFrame,
    run: impl FnOnce(&Frame<'_>, Options) -> Result<Option<String>, String>,
) -> *mut c_void {
    // SAFETY: XLA passes a valid call frame for the duration of the call (the caller's
    // contract).
    let Some(f) = (unsafe { frame.as_ref() }) else {
        return std::ptr::null_mut();
    };
    if !f.extension_start.is_null() {
        // SAFETY: `extension_start` is null or the start of a valid extension chain.
        let kind = unsafe { (*f.extension_start).kind };
        if kind == EXTENSION_METADATA {
            // SAFETY: the metadata extension (XLA_FFI_Metadata_Extension) points to a
            // metadata struct of `struct_size` bytes for the handler to fill; the fields
            // written lie within it (checked against `struct_size`).
            unsafe {
                let ext = &*(f.extension_start as *const MetadataExtension);
                if let Some(m) = ext.metadata.as_mut() {
                    if m.struct_size < METADATA_MIN_SIZE {
                        return error(f.api, ERROR_INVALID_ARGUMENT, "XLA_FFI_Metadata too small");
                    }
                    m.api_version = ApiVersion {
                        struct_size: std::mem::size_of::<ApiVersion>(),
                        extension_start: std::ptr::null_mut(),
                        major_version: 0,
                        minor_version: 3,
                    };
                    m.traits = 0;
                    if m.struct_size >= std::mem::size_of::<Metadata>() {
                        m.state_type_id = 0;
                    }
                }
            }
            return std::ptr::null_mut();
        }
    }
    if f.struct_size < CALL_FRAME_SIZE {
        // SAFETY: `api` is the frame's.
        return unsafe { error(f.api, ERROR_INVALID_ARGUMENT, "XLA_FFI_CallFrame too small") };
    }
    if f.stage != STAGE_EXECUTE {
        return std::ptr::null_mut();
    }
    let frame = Frame(f);
    // A panic must not unwind into XLA (it would abort the process): it becomes the
    // call's error.
    let done = std::panic::catch_unwind(AssertUnwindSafe(|| {
        frame.options().and_then(|o| run(&frame, o))
    }))
    .unwrap_or_else(|p| {
        let what = p
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Err(format!("internal error (a panic): {what}"))
    })
    .and_then(|warning| warning.map_or(Ok(()), |msg| warn(&msg)));
    match done {
        Ok(()) => std::ptr::null_mut(),
        // SAFETY: `api` is the frame's.
        Err(msg) => unsafe { error(f.api, ERROR_INTERNAL, &format!("diffsvg.jax: {msg}")) },
    }
}

/// Issues a `diffsvg.jax.DiffsvgWarning` (taking the GIL); an exception it raises (a
/// warnings filter set to "error") becomes the call's error.
fn warn(msg: &str) -> Result<(), String> {
    Python::attach(|py| -> PyResult<()> {
        let category = py.import("diffsvg.jax")?.getattr("DiffsvgWarning")?;
        let msg = CString::new(msg.replace('\0', " ")).expect("no NUL left");
        PyErr::warn(py, &category, &msg, 1)
    })
    .map_err(|e| e.to_string())
}

// ----- the two handlers ------------------------------------------------------------------

/// The registered scene `id`.
fn lookup(id: u64) -> Result<Arc<Registered>, String> {
    registry()
        .get(&id)
        .cloned()
        .ok_or_else(|| format!("scene {id} is not registered (the Scene was dropped)"))
}

/// Python's `repr` of a non-finite float (`nan`, `inf`, `-inf`), as the warnings of the
/// `pure_callback` path printed them.
fn py_repr(v: f64) -> String {
    if v.is_nan() {
        "nan".into()
    } else if v.is_infinite() {
        if v > 0.0 { "inf".into() } else { "-inf".into() }
    } else {
        v.to_string()
    }
}

/// The warning naming the first non-finite value of row `b` (`what`: params, d_image).
fn non_finite(what: &str, b: usize, rows: usize, i: usize, v: f64) -> String {
    let at = if rows > 1 {
        format!("row {b}, ")
    } else {
        String::new()
    };
    format!(
        "diffsvg.jax.render: {what} {at}value {i} is {} (not finite); the result is NaN",
        py_repr(v)
    )
}

/// The params operand as `(rows, n)` `f64`: a `f32` value equal to the `f32` rounding of
/// the scene's current value keeps the current `f64` value (as `Scene.set_params` does).
/// Rows with a non-finite value are replaced by the current values and marked in `bad`;
/// the returned warning names the first such value.
fn rows_of(
    reg: &Registered,
    p: &Operand,
    rows: usize,
    bad: &mut [bool],
) -> Result<(Array2<f64>, Option<String>), String> {
    let n = reg.n;
    let mut out = Array2::<f64>::zeros((rows, n));
    let current = || reg.current.get_or_init(|| reg.scene.params());
    match p.dtype {
        DTYPE_F32 => {
            let v: &[f32] = p.input(DTYPE_F32)?;
            let cur = current();
            for (o, (r, c)) in out.iter_mut().zip(v.iter().zip(cur.iter().cycle())) {
                *o = if *c as f32 == *r { *c } else { f64::from(*r) };
            }
        }
        DTYPE_F64 => {
            let v: &[f64] = p.input(DTYPE_F64)?;
            out.as_slice_mut()
                .expect("a new array is contiguous")
                .copy_from_slice(v);
        }
        d => {
            return Err(format!(
                "params: dtype code {d}, expected float32 or float64"
            ));
        }
    }
    let mut warning = None;
    for (b, mut row) in out.rows_mut().into_iter().enumerate() {
        if let Some(i) = row.iter().position(|x| !x.is_finite()) {
            warning.get_or_insert_with(|| non_finite("params", b, rows, i, row[i]));
            bad[b] = true;
            row.assign(&ArrayView1::from(current().as_slice()));
        }
    }
    Ok((out, warning))
}

/// Checks params `[batch..., n]` against the scene; the number of rows.
fn batch_rows(reg: &Registered, p: &Operand) -> Result<usize, String> {
    match p.dims.split_last() {
        Some((&n, batch)) if n == reg.n => Ok(batch.iter().product()),
        _ => Err(format!(
            "params: shape {:?} but the scene has {} parameters (did the scene change since \
             the step was compiled?)",
            p.dims, reg.n
        )),
    }
}

/// Checks an image operand `[rows..., h, w, 4]` of the scene's size.
fn check_image(reg: &Registered, op: &Operand, rows: usize, what: &str) -> Result<(), String> {
    let (w, h) = (reg.scene.width as usize, reg.scene.height as usize);
    let k = op.dims.len();
    if k < 3 || op.dims[k - 3..] != [h, w, 4] || op.len() != rows * h * w * 4 {
        return Err(format!(
            "{what}: shape {:?} but {rows} rows of a {w}x{h} scene need [{rows}, {h}, {w}, 4]",
            op.dims
        ));
    }
    Ok(())
}

fn render_options(o: &Options) -> Result<RenderOptions, String> {
    crate::render::options(o.tolerance, o.exact_overlaps).map_err(|e| e.to_string())
}

/// Writes `values` row by row into `out` (`rows × per_row`), NaN for the rows marked bad.
fn write_rows<T: Copy, U>(
    out: &mut [T],
    per_row: usize,
    values: impl IntoIterator<Item = U>,
    bad: &[bool],
    nan: T,
    fill: impl Fn(&mut [T], U),
) {
    if per_row == 0 {
        return;
    }
    for ((chunk, v), &bad) in out.chunks_exact_mut(per_row).zip(values).zip(bad) {
        if bad {
            chunk.fill(nan);
        } else {
            fill(chunk, v);
        }
    }
}

/// The forward pass of one call.
fn forward(f: &Frame<'_>, o: Options) -> Result<Option<String>, String> {
    let reg = lookup(o.scene)?;
    let opts = render_options(&o)?;
    let p = f.operand(false, 0, "params")?;
    let mut img = f.operand(true, 0, "image")?;
    let rows = batch_rows(&reg, &p)?;
    check_image(&reg, &img, rows, "image")?;
    let mut bad = vec![false; rows];
    let (x, warning) = rows_of(&reg, &p, rows, &mut bad)?;
    let images = render_rows(&reg.scene, &x.view(), o.background, &opts, &reg.rendered)?;
    let plane = reg.scene.width as usize * reg.scene.height as usize * 4;
    write_rows(
        img.output(DTYPE_F32)?,
        plane,
        images,
        &bad,
        f32::NAN,
        |c, i| c.copy_from_slice(i.data.as_flattened()),
    );
    Ok(warning)
}

/// The backward pass of one call.
fn backward(f: &Frame<'_>, o: Options) -> Result<Option<String>, String> {
    let reg = lookup(o.scene)?;
    let opts = render_options(&o)?;
    let p = f.operand(false, 0, "params")?;
    let d = f.operand(false, 1, "d_image")?;
    let mut g = f.operand(true, 0, "gradient")?;
    let rows = batch_rows(&reg, &p)?;
    check_image(&reg, &d, rows, "d_image")?;
    if g.dims != p.dims || g.dtype != p.dtype {
        return Err(format!(
            "gradient: shape {:?} (dtype code {}) for params {:?} (dtype code {})",
            g.dims, g.dtype, p.dims, p.dtype
        ));
    }
    let mut bad = vec![false; rows];
    let (x, warning) = rows_of(&reg, &p, rows, &mut bad)?;
    let dv: &[f32] = d.input(DTYPE_F32)?;
    let (w, h) = (reg.scene.width as usize, reg.scene.height as usize);
    let plane = h * w * 4;
    let mut owned: Option<Vec<f32>> = None;
    let mut d_warning = None;
    for b in 0..rows {
        let r = &dv[b * plane..(b + 1) * plane];
        if let Some(i) = r.iter().position(|x| !x.is_finite()) {
            d_warning.get_or_insert_with(|| non_finite("d_image", b, rows, i, f64::from(r[i])));
            bad[b] = true;
            owned.get_or_insert_with(|| dv.to_vec())[b * plane..(b + 1) * plane].fill(0.0);
        }
    }
    let dview = ArrayView4::from_shape((rows, h, w, 4), owned.as_deref().unwrap_or(dv))
        .map_err(|e| e.to_string())?;
    let grads = backward_rows(
        &reg.scene,
        &x.view(),
        &dview,
        o.background,
        &opts,
        &reg.rendered,
    )?;
    let n = reg.n;
    if g.dtype == DTYPE_F32 {
        write_rows(g.output(DTYPE_F32)?, n, grads, &bad, f32::NAN, |c, v| {
            c.iter_mut().zip(v).for_each(|(o, v)| *o = v as f32)
        });
    } else {
        write_rows(g.output(DTYPE_F64)?, n, grads, &bad, f64::NAN, |c, v| {
            c.copy_from_slice(&v)
        });
    }
    // The params' warning first, as the callback gave it.
    Ok(warning.or(d_warning))
}

/// The forward handler: params `[batch..., n]` -> image `f32` `[batch..., h, w, 4]`.
///
/// # Safety
/// Called by XLA with its call frame (see the module's doc).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn diffsvg_ffi_render(frame: *mut CallFrame) -> *mut c_void {
    // SAFETY: `frame` is XLA's call frame (this function's contract).
    unsafe { handle(frame, forward) }
}

/// The backward handler: params `[batch..., n]`, `d_image` `f32` `[batch..., h, w, 4]` ->
/// the gradient `[batch..., n]` in the params' dtype.
///
/// # Safety
/// Called by XLA with its call frame (see the module's doc).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn diffsvg_ffi_render_backward(frame: *mut CallFrame) -> *mut c_void {
    // SAFETY: as above.
    unsafe { handle(frame, backward) }
}
