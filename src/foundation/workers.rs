//! The threads CPU cloths step on, and mesh colliders bake on: [`ClothWorkers`] (the cloth
//! plugin's own pool) or Bevy's `ComputeTaskPool` through [`TaskPoolParallel`].

use bevy::prelude::*;
use bevy::tasks::TaskPool;

use crate::solver::{Parallel, Workers};

/// The worker threads the plugin steps CPU cloths on ([`Workers::per_core`]: one helper per
/// core besides the thread running the system), computes their meshes' normals and tangents
/// on (the cloths in parallel with each other), and bakes mesh colliders on. They spin for a moment after each parallel
/// region and then sleep, so an idle app pays nothing for them. Remove the resource to step
/// on Bevy's `ComputeTaskPool` instead (slower for one cloth: waking its threads takes about
/// as long as a substep's work at 64 × 64), or insert `ClothWorkers(Workers::new(0))` to step
/// on the calling thread only.
#[derive(Resource, Debug)]
pub struct ClothWorkers(pub Workers);

impl ClothWorkers {
    /// The pool of `workers`, or else one of no helpers (work on the calling thread alone,
    /// made once for the process): for work whose result does not depend on the threads,
    /// such as a mesh collider's bake.
    pub(crate) fn or_serial(workers: Option<&Self>) -> &Workers {
        static SERIAL: std::sync::OnceLock<Workers> = std::sync::OnceLock::new();
        workers.map_or_else(|| SERIAL.get_or_init(|| Workers::new(0)), |w| &w.0)
    }
}

impl Default for ClothWorkers {
    fn default() -> Self {
        Self(Workers::per_core())
    }
}

/// Runs solver work items on Bevy's [`ComputeTaskPool`](bevy::tasks::ComputeTaskPool).
#[derive(Clone, Copy)]
pub struct TaskPoolParallel<'a>(pub &'a TaskPool);

impl Parallel for TaskPoolParallel<'_> {
    fn for_each_mut<T: Send, F: Fn(&mut T) + Sync>(&self, items: &mut [T], f: F) {
        if items.len() < 2 || self.0.thread_num() == 0 {
            items.iter_mut().for_each(f);
            return;
        }
        let f = &f;
        self.0.scope(|s| {
            for item in items.iter_mut() {
                s.spawn(async move { f(item) });
            }
        });
    }

    fn threads(&self) -> usize {
        // The pool's threads and the thread that waits on the scope, which works too.
        self.0.thread_num() + 1
    }
}
