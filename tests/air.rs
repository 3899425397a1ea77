//! Air and wind on whole cloths (solver only, no Bevy): a falling sheet glides, a curtain
//! settles when the wind stops, a flag hangs in calm air and flutters in wind.

use bevy_cloth::solver::{
    Aerodynamics, Environment, Grid, MassDistribution, Pin, Serial, Simulation, Solver,
    SolverParams, TopologyOptions, WindField, WindParams,
};
use glam::{Quat, Vec3};

const DT: f32 = 1.0 / 60.0;

/// A `grid` cloth of `mass` kg turned by `rotation` and moved by `offset`, with `params`.
fn cloth(grid: &Grid, mass: f32, rotation: Quat, offset: Vec3, params: SolverParams) -> Simulation {
    let topology = grid.topology(TopologyOptions::default()).unwrap();
    let masses = topology.masses(mass, MassDistribution::Area);
    let start: Vec<Vec3> = grid
        .positions()
        .iter()
        .map(|p| rotation * *p + offset)
        .collect();
    Simulation::with_positions(topology, &start, &masses, params).unwrap()
}

fn mean_y(sim: &Simulation) -> f32 {
    let s = sim.state();
    (0..s.len()).map(|i| s.position(i).y).sum::<f32>() / s.len() as f32
}

/// Seconds a flat, level 1 m², 100 g sheet takes to fall 2 m.
fn fall_time(air: Aerodynamics) -> f32 {
    let grid = Grid::new(16, 16, 1.0, 1.0);
    let params = SolverParams {
        air,
        ..Default::default()
    };
    let mut sim = cloth(&grid, 0.1, Quat::IDENTITY, Vec3::ZERO, params);
    let mut t = 0.0;
    while mean_y(&sim) > -2.0 && t < 10.0 {
        sim.step(DT, &Serial);
        t += DT;
    }
    t
}

#[test]
fn a_falling_sheet_glides_in_still_air_and_drops_in_a_vacuum() {
    let vacuum = fall_time(Aerodynamics::NONE);
    let air = fall_time(Aerodynamics::default());
    // Free fall: √(2·2/9.81) = 0.64 s. In air the sheet's terminal speed is
    // √(m·g/(drag·A)) = √(0.981/0.6) ≈ 1.3 m/s, so 2 m take well over a second.
    assert!((vacuum - 0.64).abs() < 0.05, "vacuum: {vacuum} s");
    assert!(air > 1.2, "in air: {air} s");
}

/// A 1 × 1.5 m, 0.3 kg curtain pinned along its top edge, released 60° from hanging: how far
/// the middle of its bottom edge still swings (range of its horizontal position, m) between
/// 3 and 4 s after release.
fn curtain_swing(air: Aerodynamics) -> f32 {
    let grid = Grid::new(17, 25, 1.0, 1.5);
    let params = SolverParams {
        air,
        ..Default::default()
    };
    // Grid z up the curtain; turned so that it hangs 60° out from the vertical, top edge at
    // y = 0 along x.
    let hang = Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2 - core::f32::consts::FRAC_PI_3);
    let top_z = grid.positions()[grid.index(0, 0) as usize].z;
    let mut sim = cloth(
        &grid,
        0.3,
        hang,
        -(hang * Vec3::new(0.0, 0.0, top_z)),
        params,
    );
    let top: Vec<Pin> = (0..grid.columns)
        .map(|i| {
            let v = grid.index(i, 0);
            Pin {
                vertex: v,
                target: sim.state().position(v as usize),
            }
        })
        .collect();
    assert!(top.iter().all(|p| p.target.y.abs() < 1e-5));
    sim.state_mut().set_pins(top).unwrap();
    let bottom = grid.index(grid.columns / 2, grid.rows - 1) as usize;
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for step in 0..(4 * 60) {
        sim.step(DT, &Serial);
        if step >= 3 * 60 {
            let z = sim.state().position(bottom).z;
            lo = lo.min(z);
            hi = hi.max(z);
        }
    }
    hi - lo
}

#[test]
fn a_swinging_curtain_settles_in_air() {
    let air = curtain_swing(Aerodynamics::default());
    let vacuum = curtain_swing(Aerodynamics::NONE);
    println!("curtain swing 3–4 s after release: air {air} m, vacuum {vacuum} m");
    assert!(
        vacuum > 0.5,
        "the test's swing is large without air: {vacuum} m"
    );
    // Measured: 1.94 m in a vacuum, 0.11 m in air (peak to peak).
    assert!(air < 0.1 * vacuum, "in air the swing dies out: {air} m");
}

/// How a 1 × 0.6 m, 100 g flag on a vertical pole moves over 3 s after 3 s of `speed` m/s
/// wind (or calm): `(departure, tip, droop)`: the RMS distance of its vertices from their
/// best-fit plane, the RMS motion of the fly end's midpoint about its mean, both as
/// fractions of the flag's length, and how far the fly end hangs below the hoist's middle;
/// and the flapping (out-of-plane position) of the mid-height row at a quarter, half,
/// three quarters and the end of its length, one sample per step.
fn flag(speed: f32, bending: f32) -> (f32, f32, f32, [Vec<f32>; 4]) {
    let (length, height): (f32, f32) = (1.0, 0.6);
    let grid = Grid::new(33, 20, length, height);
    let params = SolverParams {
        solver: Solver::Xpbd {
            stretch: 0.0,
            shear: 1e-6,
            bending,
        },
        ..Default::default()
    };
    // Grid x along the flag, z up the pole: (x, 0, z) → (x, z, 0).
    let upright = Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2);
    let mut sim = cloth(
        &grid,
        0.1,
        upright,
        Vec3::new(length / 2.0, 2.0, 0.0),
        params,
    );
    let hoist: Vec<Pin> = (0..grid.rows)
        .map(|j| {
            let v = grid.index(0, j);
            Pin {
                vertex: v,
                target: sim.state().position(v as usize),
            }
        })
        .collect();
    sim.state_mut().set_pins(hoist).unwrap();
    let wind = WindField::new([(
        WindParams {
            velocity: Vec3::new(speed, 0.0, 0.0),
            ..Default::default()
        },
        None,
    )]);
    let fly: Vec<usize> = (0..grid.rows)
        .map(|j| grid.index(grid.columns - 1, j) as usize)
        .collect();
    let stations = [8, 16, 24, 32].map(|i| grid.index(i, grid.rows / 2) as usize);
    let mut flaps: [Vec<f32>; 4] = Default::default();
    let mut t = 0.0f64;
    let (mut tips, mut departure) = (Vec::new(), 0.0f32);
    for step in 0..(6 * 60) {
        let env = Environment {
            colliders: &[],
            wind: (speed > 0.0).then_some(&wind),
            time: t,
        };
        sim.step_in(DT, &env, &Serial);
        t += f64::from(DT);
        if step >= 3 * 60 {
            let s = sim.state();
            let tip = fly.iter().map(|&i| s.position(i)).sum::<Vec3>() / fly.len() as f32;
            tips.push(tip);
            departure += plane_rms(&(0..s.len()).map(|i| s.position(i)).collect::<Vec<_>>());
            for (flap, &v) in flaps.iter_mut().zip(&stations) {
                flap.push(s.position(v).z);
            }
        }
    }
    let mean = tips.iter().sum::<Vec3>() / tips.len() as f32;
    let tip = (tips
        .iter()
        .map(|p| (*p - mean).length_squared())
        .sum::<f32>()
        / tips.len() as f32)
        .sqrt();
    let droop = 2.0 - mean.y;
    (
        departure / tips.len() as f32 / length,
        tip / length,
        droop,
        flaps,
    )
}

/// The delay (in samples, up to `max`) by which `b` follows `a`: the shift with the largest
/// correlation of the two (means removed).
fn delay(a: &[f32], b: &[f32], max: usize) -> i32 {
    let centred = |x: &[f32]| {
        let m = x.iter().sum::<f32>() / x.len() as f32;
        x.iter().map(|v| v - m).collect::<Vec<_>>()
    };
    let (a, b) = (centred(a), centred(b));
    let n = a.len() - max;
    let corr = |k: i32| -> f32 {
        (max..n)
            .map(|t| a[t] * b[(t as i32 + k) as usize])
            .sum::<f32>()
    };
    (-(max as i32)..=max as i32)
        .max_by(|&x, &y| corr(x).total_cmp(&corr(y)))
        .unwrap_or(0)
}

/// RMS distance of `points` from their least-squares plane.
fn plane_rms(points: &[Vec3]) -> f32 {
    let n = points.len() as f32;
    let c = points.iter().sum::<Vec3>() / n;
    let mut cov = glam::Mat3::ZERO;
    for p in points {
        let d = *p - c;
        cov += glam::Mat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    // The plane's normal is the covariance's weakest direction: inverse iteration.
    let inv = (cov + glam::Mat3::IDENTITY * 1e-9).inverse();
    let mut normal = Vec3::new(0.3, 0.5, 0.8);
    for _ in 0..50 {
        normal = (inv * normal).normalize();
    }
    (points
        .iter()
        .map(|p| (*p - c).dot(normal).powi(2))
        .sum::<f32>()
        / n)
        .sqrt()
}

#[test]
fn a_flag_hangs_in_calm_air_and_flutters_in_wind() {
    let bending = bevy_cloth::solver::DEFAULT_BENDING_COMPLIANCE;
    let (departure, tip, droop, _) = flag(0.0, bending);
    println!("calm: departure {departure:.3} L, tip {tip:.3} L, droop {droop:.2} m");
    assert!(
        droop > 0.4,
        "a flag in calm air hangs from its pole: droop {droop} m"
    );
    assert!(departure < 0.01, "and stays flat: {departure}");
    for speed in [5.0, 10.0] {
        let (departure, tip, droop, flaps) = flag(speed, bending);
        println!("{speed} m/s: departure {departure:.3} L, tip {tip:.3} L, droop {droop:.2} m");
        assert!(
            droop < 0.25,
            "{speed} m/s: the flag flies out, droop {droop} m"
        );
        assert!(
            departure > 0.015,
            "{speed} m/s: ripples, departure {departure} L"
        );
        assert!(tip > 0.05, "{speed} m/s: the fly end swings, {tip} L");
        // Waves run from the hoist to the fly: each station further out flaps later than the
        // one before it (delays in 1/60 s steps, searched within ±0.25 s).
        let delays: Vec<i32> = flaps.windows(2).map(|w| delay(&w[0], &w[1], 15)).collect();
        println!("{speed} m/s: delays between the quarter stations {delays:?} steps");
        assert!(
            delays.iter().all(|&d| d > 0),
            "{speed} m/s: waves run from the hoist to the fly: delays {delays:?}"
        );
        let total = delays.iter().sum::<i32>() as f32 * DT;
        let wave_speed = 0.75 / total; // the stations span 0.75 of the 1 m flag
        assert!(
            wave_speed < 2.0 * speed,
            "{speed} m/s: the waves travel with the air, not instantly: {wave_speed} m/s"
        );
    }
}
