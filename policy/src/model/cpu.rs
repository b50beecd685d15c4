//! What the fused CPU kernels share: a row-major GEMM on slices (the `gemm` crate candle
//! itself multiplies with, on rayon's threads), a reusable scratch buffer for patch matrices,
//! and the thread setup of a training or inference process.

use std::cell::RefCell;
use std::sync::Once;

use candle_core::{CpuStorage, Layout};

/// The contiguous f32 values of a storage with a contiguous layout.
pub(crate) fn values<'a>(s: &'a CpuStorage, l: &Layout) -> candle_core::Result<&'a [f32]> {
    let data = s.as_slice::<f32>()?;
    match l.contiguous_offsets() {
        Some((start, end)) => Ok(&data[start..end]),
        None => candle_core::bail!("fused op: operands must be contiguous"),
    }
}

/// `c (+)= op(a) · op(b)`, all row-major: `a` is `[m, k]` (stored `[k, m]` when `a_t`), `b` is
/// `[k, n]` (stored `[n, k]` when `b_t`), `c` is `[m, n]`; `accumulate` adds to `c` instead of
/// overwriting it. Large products run on rayon's threads.
#[allow(clippy::too_many_arguments)]
pub(crate) fn gemm(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    a_t: bool,
    b: &[f32],
    b_t: bool,
    c: &mut [f32],
    accumulate: bool,
) {
    product(true, [m, n, k], (a, a_t), (b, b_t), c, accumulate);
}

/// [`gemm`] with the operands as `(values, transposed)`; a large product runs on rayon's
/// threads only when `split` (callers that split their work across the threads themselves
/// keep it on the calling thread, where a split of its own would compete with theirs).
pub(crate) fn product(
    split: bool,
    [m, n, k]: [usize; 3],
    (a, a_t): (&[f32], bool),
    (b, b_t): (&[f32], bool),
    c: &mut [f32],
    accumulate: bool,
) {
    let a = if a_t {
        Strided::new(a, 1, m)
    } else {
        Strided::new(a, k, 1)
    };
    let b = if b_t {
        Strided::new(b, 1, k)
    } else {
        Strided::new(b, n, 1)
    };
    strided_product(split, [m, n, k], a, b, (c, n), accumulate);
}

/// A matrix operand read in place: element (i, j) is `values[i · rs + j · cs]`.
#[derive(Clone, Copy)]
pub(crate) struct Strided<'a> {
    pub values: &'a [f32],
    pub rs: usize,
    pub cs: usize,
}

impl<'a> Strided<'a> {
    pub(crate) fn new(values: &'a [f32], rs: usize, cs: usize) -> Self {
        Strided { values, rs, cs }
    }
    /// Whether every element of a `rows × cols` matrix lies inside `values`.
    fn holds(&self, rows: usize, cols: usize) -> bool {
        rows == 0 || cols == 0 || self.values.len() > (rows - 1) * self.rs + (cols - 1) * self.cs
    }
}

/// [`product`] on strided operands: `c` (row stride `c.1`, unit column stride) `(+)= a · b`,
/// `a` `[m, k]`, `b` `[k, n]`.
#[allow(unsafe_code)]
pub(crate) fn strided_product(
    split: bool,
    [m, n, k]: [usize; 3],
    a: Strided,
    b: Strided,
    (c, c_rs): (&mut [f32], usize),
    accumulate: bool,
) {
    let cm = Strided::new(c, c_rs, 1);
    assert!(a.holds(m, k) && b.holds(k, n) && cm.holds(m, n) && c_rs >= n);
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            c.chunks_mut(c_rs).take(m).for_each(|r| r[..n].fill(0.0));
        }
        return;
    }
    let par = if split && m * n * k >= 1 << 18 {
        gemm::Parallelism::Rayon(0)
    } else {
        gemm::Parallelism::None
    };
    // SAFETY: the asserts above keep every index the strides reach inside the slices; `c`
    // does not alias `a` or `b` (a `&mut` borrow).
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            c.as_mut_ptr(),
            1,
            c_rs as isize,
            accumulate,
            a.values.as_ptr(),
            a.cs as isize,
            a.rs as isize,
            b.values.as_ptr(),
            b.cs as isize,
            b.rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            par,
        );
    }
}

/// Whether `samples` of a training batch run in chunks side by side, one per thread, each
/// chunk's products on its thread alone (the convolution kernels' shared rule): with samples
/// enough for several per thread. A few samples (inference) keep one split GEMM.
pub(crate) fn side_by_side(samples: usize) -> bool {
    let threads = rayon::current_num_threads();
    threads >= 2 && samples >= 4 * threads
}

/// `out` = the sum of `parts` (each `out.len()` values), added in order: per-thread partial
/// sums added this way give the same bits whichever thread computed which part.
pub(crate) fn sum_in_order<'a>(out: &mut [f32], parts: impl IntoIterator<Item = &'a [f32]>) {
    out.fill(0.0);
    for part in parts {
        out.iter_mut().zip(part).for_each(|(a, b)| *a += b);
    }
}

/// Runs `f` compiled for the widest vector instructions this CPU has (AVX-512, else AVX2 and
/// FMA; found at run time, as the GEMM crate picks its kernels): the crate is built for
/// baseline x86-64, whose loops vectorize 4 lanes wide at most, and `f`'s loops, inlined
/// here, 8 or 16 wide. Element-wise results do not change: Rust does not fuse or reorder
/// float operations, whatever the instruction set.
#[inline(always)]
pub(crate) fn vectorized<R>(f: impl FnOnce() -> R) -> R {
    pulp::Arch::new().dispatch(f)
}

thread_local! {
    static SCRATCH: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// Runs `f` with a scratch buffer of at least `len` values (contents unspecified), kept
/// between calls on this thread: patch matrices are rebuilt every call, and allocating them
/// anew each time costs a page fault per 4 KiB (the kernel zeroes every page).
pub(crate) fn with_scratch<R>(len: usize, f: impl FnOnce(&mut [f32]) -> R) -> R {
    let mut buf = SCRATCH.with(|s| std::mem::take(&mut *s.borrow_mut()));
    if buf.len() < len {
        buf = vec![0f32; len];
    }
    let r = f(&mut buf[..len]);
    SCRATCH.with(|s| *s.borrow_mut() = buf);
    r
}

/// Runs `f` on one of rayon's worker threads. The parallel ops `f` starts then split on that
/// thread and the other workers steal the halves; called from any other thread, every op
/// queues a job for the pool and parks the caller until it is done — two thread wake-ups per
/// op, and a DDIM-10 sample of ScaleDP-Ti starts about 1,500 ops, most of them small.
pub(crate) fn on_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    rayon::scope(|_| f())
}

static THREADS: Once = Once::new();

/// Sets up the process's CPU threads for training and inference, once: candle's
/// element-wise ops get no thread pool of their own (`CANDLE_NUM_THREADS=1`, unless the
/// variable is set already), so matrix products and the fused kernels share rayon's pool.
///
/// candle 0.11 runs large element-wise ops on a second, spinning pool of its own beside
/// rayon's: on a two-core machine its waiting threads took the cores from the threads doing
/// the work (half of a ScaleDP-Ti step went to spinning, and the step ran on about one core).
/// Called before the model's first op; the variable is read when candle's pool is created.
pub fn init_threads() {
    THREADS.call_once(|| {
        if std::env::var_os("CANDLE_NUM_THREADS").is_none() {
            std::env::set_var("CANDLE_NUM_THREADS", "1");
        }
    });
}
