//! Live numbers per cloth: step time, max and mean strain, torn edges, over the last few
//! seconds, so a user sees what each slider costs and buys.

use std::collections::VecDeque;

use bevy::platform::collections::HashMap;
use bevy::prelude::*;

use crate::cloth::ClothSim;
use crate::gpu::ClothBackendInUse;

/// How many seconds of history the plots show.
pub const HISTORY_SECONDS: f64 = 10.0;

/// Samples per second kept (strain is measured over every edge, so not every frame).
pub const SAMPLES_PER_SECOND: f64 = 20.0;

/// One sample of a cloth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Seconds since the app started.
    pub time: f64,
    /// Wall-clock milliseconds of its last CPU step (0 on the GPU).
    pub step_ms: f32,
    /// Largest relative edge stretch, `|l − l₀| / l₀`.
    pub max_strain: f32,
    /// Mean relative edge stretch.
    pub mean_strain: f32,
    /// Edges torn so far.
    pub torn: usize,
    /// Whether the cloth was asleep.
    pub asleep: bool,
}

/// The recent samples of every cloth.
#[derive(Resource, Debug, Default)]
pub struct ClothStats {
    /// Per cloth entity, oldest first, at most [`HISTORY_SECONDS`] long.
    pub cloths: HashMap<Entity, VecDeque<Sample>>,
    last: f64,
}

impl ClothStats {
    /// The newest sample of a cloth.
    #[must_use]
    pub fn latest(&self, cloth: Entity) -> Option<&Sample> {
        self.cloths.get(&cloth).and_then(|h| h.back())
    }
}

/// Takes a sample of every cloth, [`SAMPLES_PER_SECOND`] times a second.
pub(crate) fn record(
    time: Res<Time<Real>>,
    mut stats: ResMut<ClothStats>,
    cloths: Query<(Entity, &ClothSim, Option<&ClothBackendInUse>)>,
) {
    let now = time.elapsed_secs_f64();
    if now - stats.last < 1.0 / SAMPLES_PER_SECOND && stats.last > 0.0 {
        return;
    }
    stats.last = now;
    stats.cloths.retain(|e, _| cloths.contains(*e));
    for (e, sim, backend) in &cloths {
        let history = stats.cloths.entry(e).or_default();
        let asleep = sim.is_sleeping();
        // An asleep cloth has not moved: its strain is the last sample's (no pass over edges).
        let (max_strain, mean_strain) = match history.back() {
            Some(last) if asleep && last.asleep => (last.max_strain, last.mean_strain),
            _ => {
                let s = sim.simulation().strain();
                (s.max, s.mean)
            }
        };
        let gpu = backend.is_some_and(|b| b.gpu);
        let sample = Sample {
            time: now,
            step_ms: if gpu { 0.0 } else { sim.step_seconds() * 1e3 },
            max_strain,
            mean_strain,
            torn: sim.torn_edges(),
            asleep,
        };
        history.push_back(sample);
        while history
            .front()
            .is_some_and(|s| now - s.time > HISTORY_SECONDS)
        {
            history.pop_front();
        }
    }
}
