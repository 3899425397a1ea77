//! Air and wind: how a cloth meets the air it moves through ([`Aerodynamics`]: drag, lift,
//! skin friction per vertex) and the air's own motion ([`WindField`]: wind with gusts and
//! turbulence, sampled once a step on a coarse [`AirGrid`] around the cloth).

mod aero;
mod wind;

pub(crate) use aero::air_velocity_changes4;
pub use aero::{Aerodynamics, air_force, air_velocity_change, vertex_area_vectors};
pub use wind::{AirGrid, WindField, WindParams, WindRegion};
