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

    /// Steps the cloth with `par`, keeping its report and the seconds it took.
    fn step_timed(&mut self, dt: f32, env: &Environment<'_>, par: &impl Parallel) {
        let start = std::time::Instant::now();
        self.report = self.sim.step_in(dt, env, par);
        self.seconds = start.elapsed().as_secs_f32();
    }
}

/// How many times its vertices, substeps and iterations a self-colliding cloth's work counts
/// in [`step_many`].
const SELF_COLLISION_WEIGHT: usize = 5;

/// Steps several cloths by `dt` in one environment, using every thread `par` has.
///
/// Each cloth's work is its vertex count times its substeps and iterations. A cloth with more
/// than its share of the whole (total work over [`Parallel::threads`]) that can be cut into
/// parts ([`default_part_count`](crate::solver::default_part_count) > 1: 4096 vertices and more) is stepped on its own with its
/// parts in parallel, one such cloth after another. All the others are then stepped in
/// parallel with each other, each on one thread, the biggest first (a self-colliding cloth's
/// work counted five times), except that one left alone, or a self-colliding one with twice
/// the work of all those after it, is first stepped with `par`: its self-collision runs in
/// parallel without parts. So 64 cloths of 16² cost
/// about what one cloth of 128² costs, and one 128² cloth with 64 small ones keeps both
/// threads of a 2-core machine busy. Each cloth's result is the same as
/// [`Simulation::step_in`] alone would give, bit for bit (a cloth's own step never depends
/// on the thread count).
pub fn step_many(items: &mut [ManyItem<'_>], dt: f32, env: &Environment<'_>, par: &impl Parallel) {
    let work = |sim: &Simulation| {
        sim.state().len() * (sim.params().substeps.max(1) * sim.params().iterations.max(1)) as usize
    };
    // Self-collision costs a cloth several times its constraints (4.5 to 6 times the plain
    // step in the `cape` example and the scene-cost benchmark): for the order and for who gets
    // the threads, a self-colliding cloth's work counts five times.
    let weight = |sim: &Simulation| {
        let factor = if sim.features().self_collision.is_some() {
            SELF_COLLISION_WEIGHT
        } else {
            1
        };
        work(sim) * factor
    };
    let total: usize = items.iter().map(|i| work(i.sim)).sum();
    let share = total / par.threads().max(1);
    let mut rest: Vec<&mut ManyItem<'_>> = Vec::with_capacity(items.len());
    for item in items.iter_mut() {
        if item.sim.batches().part_count() > 1 && work(item.sim) > share {
            item.step_timed(dt, env, par);
        } else {
            rest.push(item);
        }
    }
    // Biggest first: the pool hands tasks out roughly in order, so the long ones start early.
    rest.sort_by_key(|i| core::cmp::Reverse(weight(i.sim)));
    // What runs in parallel below the parts (self-collision's query and pass, in chunks of
    // vertices) can use every thread where one cloth would otherwise keep one busy while the
    // others are done: a cloth left on its own, and a self-colliding one with at least twice
    // the weight of all those after it, are stepped with `par`, one after another, before the
    // rest are shared out. (Stepped with `Serial`, a 1 089-vertex banner draped with
    // self-collision kept one core of two busy, 13 ms a step.)
    let mut first = 0;
    let mut after: usize = rest.iter().map(|i| weight(i.sim)).sum();
    while first < rest.len() {
        let item = &mut rest[first];
        // The weight of those after this one.
        after -= weight(item.sim);
        let alone = after == 0
            || (item.sim.features().self_collision.is_some() && weight(item.sim) >= 2 * after);
        if !alone {
            break;
        }
        item.step_timed(dt, env, par);
        first += 1;
    }
    let rest = &mut rest[first..];
    par.for_each_mut(rest, |item| {
        item.step_timed(dt, env, &Serial);
    });
}
