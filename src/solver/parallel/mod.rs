//! How the solver runs independent work items: serially or on a thread pool.
//!
//! The solver never starts threads on its own. It hands a slice of independent items (one per
//! vertex range, or one per cloth) to a [`Parallel`] implementation: [`Workers`] (a pool you
//! create, made for the solver's short parallel regions; the Bevy plugin keeps one), Bevy's
//! task pool through `TaskPoolParallel`, or [`Serial`].

mod workers;

pub use workers::Workers;

/// Runs a function over independent items, possibly on several threads.
pub trait Parallel: Sync {
    /// Calls `f` once for every item; returns when all calls have returned. Items may be
    /// processed in any order and concurrently: `f` must not depend on the order.
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F);

    /// How many items can run at once (threads working, the calling one included); used to
    /// balance work, never for correctness.
    fn threads(&self) -> usize {
        1
    }
}

/// Items a parallel region over a per-vertex array hands out: vertices a work item maps.
pub(crate) const CHUNK: usize = 4096;

/// `out[i] = f(i)` for every `i < n` (`out` cleared and resized first), in chunks of
/// [`CHUNK`] on `par`.
pub(crate) fn map_chunks<T: Copy + Default + Send>(
    par: &impl Parallel,
    out: &mut Vec<T>,
    n: usize,
    f: impl Fn(usize) -> T + Sync,
) {
    out.clear();
    out.resize(n, T::default());
    let mut chunks: Vec<(usize, &mut [T])> = out
        .chunks_mut(CHUNK)
        .enumerate()
        .map(|(k, c)| (k * CHUNK, c))
        .collect();
    par.for_each_mut(&mut chunks, |(first, chunk)| {
        for (k, o) in chunk.iter_mut().enumerate() {
            *o = f(*first + k);
        }
    });
}

/// Runs everything on the calling thread, in order.
#[derive(Clone, Copy, Debug, Default)]
pub struct Serial;

impl Parallel for Serial {
    #[inline]
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F) {
        items.iter_mut().for_each(f);
    }
}
