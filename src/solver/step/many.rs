//! [`step_many`]: several cloths stepped together, sharing the threads.

use super::simulation::{Environment, Simulation, StepReport};
use crate::solver::parallel::{Parallel, Serial};

/// One cloth of [`step_many`]: the simulation and, after the call, what its step reported.
#[derive(Debug)]
pub struct ManyItem<'a> {
    /// The cloth.
    pub sim: &'a mut Simulation,
    /// Its step's report (set by [`step_many`]).
    pub report: StepReport,
    /// Wall-clock seconds its step took (set by [`step_many`]; with other cloths running on
    /// the other threads at the same time).
    pub seconds: f32,
}

impl<'a> ManyItem<'a> {
    /// One item per simulation of `sims`, reports empty.
    pub fn each(sims: &'a mut [Simulation]) -> Vec<Self> {
        sims.iter_mut()
            .map(|sim| ManyItem {
                sim,
                report: StepReport::default(),
                seconds: 0.0,
            })
            .collect()
    }
}

/// Steps several cloths by `dt` in one environment, using every thread `par` has.
///
/// Each cloth's work is its vertex count times its substeps and iterations. A cloth with more
/// than its share of the whole (total work over [`Parallel::threads`]) that can be cut into
/// parts ([`default_part_count`](crate::solver::default_part_count) > 1: 4096 vertices and more) is stepped on its own with its
/// parts in parallel, one such cloth after another. All the others are then stepped in
/// parallel with each other, each on one thread, the biggest first (one left alone is stepped
/// with `par`, for what of its step runs in parallel without parts). So 64 cloths of 16² cost
/// about what one cloth of 128² costs, and one 128² cloth with 64 small ones keeps both
/// threads of a 2-core machine busy. Each cloth's result is the same as
/// [`Simulation::step_in`] alone would give, bit for bit (a cloth's own step never depends
/// on the thread count).
pub fn step_many(items: &mut [ManyItem<'_>], dt: f32, env: &Environment<'_>, par: &impl Parallel) {
    let work = |sim: &Simulation| {
        sim.state().len() * (sim.params().substeps.max(1) * sim.params().iterations.max(1)) as usize
    };
    let total: usize = items.iter().map(|i| work(i.sim)).sum();
    let share = total / par.threads().max(1);
    let mut rest: Vec<&mut ManyItem<'_>> = Vec::with_capacity(items.len());
    for item in items.iter_mut() {
        if item.sim.batches().part_count() > 1 && work(item.sim) > share {
            let start = std::time::Instant::now();
            item.report = item.sim.step_in(dt, env, par);
            item.seconds = start.elapsed().as_secs_f32();
        } else {
            rest.push(item);
        }
    }
    // A cloth left on its own has every thread to itself: whatever of its step runs in
    // parallel below the parts (self-collision's query and pass, in chunks of vertices) uses
    // them. (Stepped with `Serial`, a 1 089-vertex banner draped with self-collision kept one
    // core of two busy, 13 ms a step.)
    if let [item] = &mut rest[..] {
        let start = std::time::Instant::now();
        item.report = item.sim.step_in(dt, env, par);
        item.seconds = start.elapsed().as_secs_f32();
        return;
    }
    // Biggest first: the pool hands tasks out roughly in order, so the long ones start early.
    rest.sort_by_key(|i| core::cmp::Reverse(work(i.sim)));
    par.for_each_mut(&mut rest, |item| {
        let start = std::time::Instant::now();
        item.report = item.sim.step_in(dt, env, &Serial);
        item.seconds = start.elapsed().as_secs_f32();
    });
}
