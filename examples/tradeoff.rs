//! What speed costs in accuracy: sweeps solver × substeps × iterations × grid size on one
//! standard scene and prints one JSON line per case.
//!
//! The scene: a 1 m × 1 m cloth of n×n vertices, 1 kg spread evenly, starting flat and
//! horizontal, pinned at the two corners of one edge, gravity 9.81 m/s², no collisions;
//! 60 frames of 1/60 s. Stretch is as stiff as each solver allows (XPBD compliance 0, PBD
//! stiffness 1); XPBD shear 1e-6 and the library's default bending (isometric, the default
//! fabric's `B` = 1e-4 N·m; `--bending dihedral` takes the dihedral model at compliance 1e-3,
//! the setting earlier tables used) and 1.0 / 0.5 stiffness for PBD; the lab solver has no
//! bending. No air (the peer has none). The solver `xpbd+tethers` is the XPBD scene with
//! every vertex tethered to both pins (`TetherParams::default()`, long-range attachments),
//! at 5, 10 and 20 substeps × 1 iteration; the budget summaries leave it out.
//!
//! Per case: `ms_per_frame` (median wall time of a step over the frames after 10 of warm-up),
//! `max_strain` and `mean_strain` (|length − rest|/rest over all edges at the end), and
//! `ref_mean`/`ref_max` (distance in metres of the final drape from a converged reference:
//! XPBD with `--reference-substeps` substeps, same n). Then, per n, the lowest max strain any
//! case reached within 1, 4 and 16 ms per frame.
//!
//! ```text
//! cargo run --release --example tradeoff                     # full sweep (a few minutes)
//! cargo run --release --example tradeoff -- --quick          # a handful of cases
//! cargo run --release --example tradeoff -- --sizes 64 --solvers xpbd --substeps 10 --iterations 1
//! ```
//! `--peer "PYTHON SCRIPT"` also runs the peer benchmark (pypbd's `pbd_cloth_bench.py`, see
//! `docs/performance.md`) on the same scene in the same run, XPBD × 1 iteration at a few substep counts
//! per size, prints its JSON lines and, per size, a `against_peer_xpbd_10x1` summary.
//! `--plot FILE.png` draws max strain against ms per frame (log–log, one curve per size,
//! ours and the peer's points) into a PNG.
//!
//! `--scene-costs` instead measures what each scene feature costs on the 64² and 256² scenes
//! (XPBD 10 × 1): nothing, a sphere collider under the cloth, wind, self-collision, tethers,
//! tethers and self-collision (a sheet that hangs at its length), tearing (threshold never
//! reached), and everything at once; with a feature off, its code
//! does not run, so `plain` is the cost of every scene without it. Tethers also report their
//! effect on `max_strain`. `--variants plain,self_collision` runs only those rows;
//! `--parts N` steps each cloth in N parts instead of `solver::default_part_count`'s
//! (to see what the partition costs on a machine's cores).
//!
//! `--many`: 64 cloths of 16² against one of 128² (the same vertex count) stepped together
//! with `step_many`, and one 128² with 64 × 16² on all threads against one thread.
//!
//! `--sleep`: the standard scene with damping 2/s until it sleeps, the median awake step
//! against the median asleep step (`--tethers`: with tethers to both pins).
//!
//! `--backend gpu`: the standard scene (XPBD 10 × 1) at 64², 128², 256² and 512² (`--sizes`),
//! without and with self-collision, on the CPU and on the GPU kernels (`src/gpu`) in the same
//! run, on the first wgpu adapter: CPU ms per frame, GPU wall time per frame (submit to done),
//! GPU time per stage from timestamp queries where the adapter has them, the dispatches a
//! frame records (and its busiest substep), and the max strain of both. With `--many`:
//! 64 cloths of 32² and 16 of 64² in one GPU world against `step_many` on the CPU. On
//! llvmpipe (software Vulkan) the GPU figures check correctness and count dispatches, not
//! speed.
//!
//! Other flags: `--frames N`, `--threads N` (default: all cores), `--repeat N` (runs per case, the
//! fastest median counts; default 3), `--reference-substeps N`, `--markdown` (also print
//! tables on stderr).

#[path = "support/mod.rs"]
mod support;

use std::time::Instant;

use bevy_cloth::gpu::{DispatchCount, GpuFrame, GpuKernels, GpuStage, GpuWorld};
use bevy_cloth::solver::{
    Aerodynamics, BendingModel, Collider, DEFAULT_BENDING_COMPLIANCE, Environment, Features,
    HangingCloth, ManyItem, Pose, SelfCollision, Shape, Simulation, Sleep, Solver, SolverParams,
    TetherParams, WindField, WindParams, Workers, position_distance, step_many,
};
use glam::{Vec3, Vec4};
use support::{Args, Json};

const DT: f32 = 1.0 / 60.0;
const DAMPING: f32 = 0.1;
const WARMUP: usize = 10;

fn list<T: std::str::FromStr + Clone>(args: &Args, key: &str, default: &[T]) -> Vec<T> {
    match args.rest.get(key) {
        None => default.to_vec(),
        Some(v) => v
            .split(',')
            .map(|s| {
                s.trim().parse().unwrap_or_else(|_| {
                    eprintln!("--{key}: cannot parse {s:?}");
                    std::process::exit(2)
                })
            })
            .collect(),
    }
}

/// The bending model of the standard scene: the library's default (isometric, with the
/// default fabric's `B` = 1e-4 N·m) or the dihedral model with the peer's setting.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Bending {
    Isometric,
    Dihedral,
}

impl Bending {
    fn parse(args: &Args) -> Self {
        match args.rest.get("bending").map(String::as_str) {
            None | Some("isometric") => Bending::Isometric,
            Some("dihedral") => Bending::Dihedral,
            Some(other) => {
                eprintln!("--bending {other:?}: use isometric or dihedral");
                std::process::exit(2)
            }
        }
    }

    fn name(self) -> &'static str {
        match self {
            Bending::Isometric => "isometric",
            Bending::Dihedral => "dihedral",
        }
    }
}

fn solver(name: &str, h: f32, bending: Bending) -> Solver {
    match name {
        "xpbd" => Solver::Xpbd {
            stretch: 0.0,
            shear: 1e-6,
            bending: match bending {
                Bending::Isometric => DEFAULT_BENDING_COMPLIANCE,
                Bending::Dihedral => 1e-3,
            },
        },
        "pbd" => Solver::Pbd {
            stretch: 1.0,
            shear: 1.0,
            bending: 0.5,
        },
        "lab" => Solver::Lab {
            velocity_keep: 1.0 / (1.0 + DAMPING * h),
        },
        other => {
            eprintln!("unknown solver {other:?}: use xpbd, pbd or lab");
            std::process::exit(2)
        }
    }
}

fn scene(n: u32, name: &str, substeps: u32, iterations: u32, bending: Bending) -> Simulation {
    // `xpbd+tethers`: the XPBD scene with each vertex tethered to both pins.
    let (name, tethered) = match name.strip_suffix("+tethers") {
        Some(base) => (base, true),
        None => (name, false),
    };
    let mut scene = HangingCloth::new(n);
    scene.options.bending = match bending {
        Bending::Isometric => BendingModel::Isometric,
        Bending::Dihedral => BendingModel::Dihedral,
    };
    scene.params = SolverParams {
        solver: solver(name, DT / substeps as f32, bending),
        substeps,
        iterations,
        damping: DAMPING,
        air: Aerodynamics::NONE,
        // Measured awake (`--sleep` measures sleeping).
        sleep: Sleep::NEVER,
        ..Default::default()
    };
    if tethered {
        scene.features.tethers = Some(TetherParams::default());
    }
    scene.build().unwrap()
}

struct Outcome {
    ms: f64,
    ref_mean: f32,
    max_strain: f32,
    mean_strain: f32,
    positions: Vec<Vec4>,
    nan: usize,
}

/// Runs the scene `repeat` times (once if a run takes over 20 ms a frame); the time is the
/// lowest of the per-run medians (the machine is shared: the minimum is the steadiest estimate
/// of what the work itself costs). Every run computes the same result, so accuracy comes from
/// the last.
fn simulate(make: impl Fn() -> Simulation, frames: usize, repeat: usize, par: &Workers) -> Outcome {
    let mut best = f64::INFINITY;
    let mut sim = make();
    for r in 0..repeat.max(1) {
        // Slow cases are measured once: their noise is small relative to their cost.
        if r > 0 && best > 20.0 {
            break;
        }
        if r > 0 {
            sim = make();
        }
        let mut times = Vec::with_capacity(frames);
        for _ in 0..frames {
            let t = Instant::now();
            sim.step(DT, par);
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let mut measured: Vec<f64> = times.iter().skip(WARMUP.min(frames / 2)).copied().collect();
        measured.sort_by(f64::total_cmp);
        best = best.min(measured[measured.len() / 2]);
    }
    let strain = sim.strain();
    Outcome {
        ms: best,
        ref_mean: 0.0,
        max_strain: strain.max,
        mean_strain: strain.mean,
        nan: sim.state().non_finite_count(),
        positions: sim.state().positions.clone(),
    }
}

/// One scene variant: which features are on.
#[derive(Clone, Copy)]
struct Variant {
    name: &'static str,
    collider: bool,
    wind: bool,
    self_collision: bool,
    tethers: bool,
    tearing: bool,
}

fn scene_costs(args: &Args, par: &Workers, threads: usize) {
    let off = Variant {
        name: "plain",
        collider: false,
        wind: false,
        self_collision: false,
        tethers: false,
        tearing: false,
    };
    let variants = [
        off,
        Variant {
            name: "collider",
            collider: true,
            ..off
        },
        Variant {
            name: "wind",
            wind: true,
            ..off
        },
        Variant {
            name: "self_collision",
            self_collision: true,
            ..off
        },
        Variant {
            name: "tethers",
            tethers: true,
            ..off
        },
        Variant {
            name: "tethers_self_collision",
            tethers: true,
            self_collision: true,
            ..off
        },
        Variant {
            name: "tearing",
            tearing: true,
            ..off
        },
        Variant {
            name: "everything",
            collider: true,
            wind: true,
            self_collision: true,
            tethers: true,
            tearing: true,
        },
    ];
    let frames = args.frames.unwrap_or(60) as usize;
    let repeat: usize = args.get("repeat", 3);
    let sphere = [Collider::fixed(
        Shape::Sphere { radius: 0.25 },
        Pose::at(glam::Vec3::new(0.0, -0.6, 0.3)),
        0.01,
        0.4,
    )];
    let wind = WindField::new([(WindParams::default(), None)]);
    let wanted: Vec<String> = list(args, "variants", &[]);
    let parts: Option<usize> = args
        .rest
        .contains_key("parts")
        .then(|| args.get("parts", 1));
    for n in list(args, "sizes", &[64u32, 256]) {
        for v in variants
            .into_iter()
            .filter(|v| wanted.is_empty() || wanted.iter().any(|w| w == v.name))
        {
            let make = || {
                let mut sim = scene(n, "xpbd", 10, 1, Bending::parse(args));
                let spacing = 1.0 / (n - 1) as f32;
                sim.set_features(Features {
                    self_collision: v.self_collision.then_some(SelfCollision {
                        thickness: spacing,
                        friction: 0.2,
                    }),
                    tethers: v.tethers.then(TetherParams::default),
                    tear_threshold: v.tearing.then_some(1000.0),
                })
                .unwrap();
                if v.wind {
                    // Wind acts through the cloth's air coefficients.
                    let params = SolverParams {
                        air: Aerodynamics::default(),
                        ..*sim.params()
                    };
                    sim.set_params(params).unwrap();
                }
                if let Some(parts) = parts {
                    sim.set_part_count(parts);
                }
                sim
            };
            let env = Environment {
                colliders: if v.collider { &sphere } else { &[] },
                wind: v.wind.then_some(&wind),
                time: 0.0,
            };
            let mut best = f64::INFINITY;
            let mut sim = make();
            for r in 0..repeat.max(1) {
                if r > 0 && best > 20.0 {
                    break;
                }
                sim = make();
                let mut times = Vec::with_capacity(frames);
                for _ in 0..frames {
                    let t = Instant::now();
                    sim.step_in(DT, &env, par);
                    times.push(t.elapsed().as_secs_f64() * 1e3);
                }
                let mut m: Vec<f64> = times.iter().skip(WARMUP.min(frames / 2)).copied().collect();
                m.sort_by(f64::total_cmp);
                best = best.min(m[m.len() / 2]);
            }
            println!(
                "{}",
                Json::default()
                    .str("scene_cost", v.name)
                    .num("n", n)
                    .num("substeps", 10)
                    .num("iterations", 1)
                    .num("ms_per_frame", (best * 1e4).round() / 1e4)
                    .num("max_strain", sim.strain().max)
                    .num("nan_count", sim.state().non_finite_count() as f64)
                    .num("threads", threads as f64)
                    .num("parts", sim.batches().part_count() as f64)
            );
        }
    }
}

/// A peer measurement: the peer's median ms per frame and max strain on the same scene.
struct PeerPoint {
    n: u32,
    substeps: u32,
    iterations: u32,
    ms: f64,
    max_strain: f64,
}

/// The number after `"key":` in a JSON line (the peer prints flat JSON).
fn json_number(line: &str, key: &str) -> Option<f64> {
    let at = line.find(&format!("\"{key}\""))? + key.len() + 2;
    let rest = line[at..].trim_start().strip_prefix(':')?.trim_start();
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || "+-.eE".contains(c)))
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// Frames the peer runs untimed after its first.
const PEER_WARMUP: usize = 3;

/// Runs the peer benchmark (`--peer "PYTHON SCRIPT"`: pypbd's `pbd_cloth_bench.py`, see
/// `docs/performance.md`) on the standard scene, XPBD with dihedral bending, and prints its JSON line.
fn run_peer(
    peer: &str,
    n: u32,
    substeps: u32,
    iterations: u32,
    frames: usize,
    threads: usize,
) -> Option<PeerPoint> {
    let mut words = peer.split_whitespace();
    let program = words.next()?;
    let out = std::process::Command::new(program)
        .args(words)
        .args(["--n", &n.to_string()])
        .args(["--substeps", &substeps.to_string()])
        .args(["--iterations", &iterations.to_string()])
        // The peer steps one frame (building its colouring) and `--warmup` frames before the
        // `--frames` it times: together they must be our `frames`, or the two strains are
        // read at different moments of the swing (they change by ±40 % within 0.1 s).
        .args(["--method", "xpbd", "--warmup", &PEER_WARMUP.to_string()])
        .args([
            "--frames",
            &frames.saturating_sub(1 + PEER_WARMUP).max(1).to_string(),
        ])
        .env("OMP_NUM_THREADS", threads.to_string())
        .output();
    let out = match out {
        Ok(o) if o.status.success() => o,
        Ok(o) => {
            eprintln!("peer failed: {}", String::from_utf8_lossy(&o.stderr));
            return None;
        }
        Err(e) => {
            eprintln!("cannot run the peer {program:?}: {e}");
            return None;
        }
    };
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().rev().find(|l| l.starts_with('{'))?;
    println!("{line}");
    let ours = frames as f64 * f64::from(DT);
    match json_number(line, "sim_time_s") {
        Some(t) if (t - ours).abs() < 1e-3 => {}
        other => eprintln!(
            "the peer simulated {other:?} s, we simulate {ours} s: its strain is from another moment"
        ),
    }
    Some(PeerPoint {
        n,
        substeps,
        iterations,
        ms: json_number(line, "ms_per_frame_median")?,
        max_strain: json_number(line, "max_edge_strain")?,
    })
}

/// Draws max strain against ms per frame, log–log, one curve per size (ours: XPBD, one
/// iteration, by substeps) and the peer's points in the same colour.
fn draw_plot(
    path: &str,
    rows: &[(String, u32, u32, u32, Outcome)],
    peer: &[PeerPoint],
    threads: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    use plotters::prelude::*;
    plotters::style::register_font(
        "sans-serif",
        FontStyle::Normal,
        bevy::text::DEFAULT_FONT_DATA,
    )
    .map_err(|_| "cannot load the font")?;
    let (w, h) = (1240u32, 640u32);
    let mut buffer = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        // The legend gets a panel of its own, so it covers no point.
        let (plot_area, legend_area) = root.split_horizontally(w - 300);
        let shown = |r: &&(String, u32, u32, u32, Outcome)| {
            (r.0 == "xpbd" || r.0 == "xpbd+tethers")
                && r.3 == 1
                && r.4.nan == 0
                && r.4.max_strain > 0.0
        };
        let xs = rows
            .iter()
            .filter(shown)
            .map(|r| r.4.ms)
            .chain(peer.iter().map(|p| p.ms));
        let ys = rows
            .iter()
            .filter(shown)
            .map(|r| f64::from(r.4.max_strain) * 100.0)
            .chain(peer.iter().map(|p| p.max_strain * 100.0));
        let (x0, x1) = xs.fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x), b.max(x)));
        let (y0, y1) = ys.fold((f64::MAX, f64::MIN), |(a, b), y| (a.min(y), b.max(y)));
        let mut chart = ChartBuilder::on(&plot_area)
            .caption(
                // Bevy's built-in font is an ASCII subset: no ² or en dash here.
                format!("Max strain against time per frame (1 m x 1 m cloth, {threads} threads)"),
                ("sans-serif", 22),
            )
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(
                (x0 * 0.7..x1 * 1.4).log_scale(),
                (y0.max(0.01) * 0.7..y1 * 1.4).log_scale(),
            )?;
        chart
            .configure_mesh()
            .x_desc("ms per frame (log)")
            .y_desc("max strain, % (log)")
            .label_style(("sans-serif", 16))
            .draw()?;
        let mut sizes: Vec<u32> = rows.iter().map(|r| r.1).collect();
        sizes.dedup();
        let palette = [
            RGBColor(30, 90, 200),
            RGBColor(210, 40, 40),
            RGBColor(20, 150, 60),
            RGBColor(150, 60, 180),
            RGBColor(230, 140, 0),
            BLACK,
        ];
        // (label, what marks it, colour): drawn in the legend panel after the chart.
        #[derive(Clone, Copy)]
        enum Mark {
            Line,
            Dashed,
            Triangle,
        }
        let mut legend: Vec<(String, Mark, RGBColor)> = Vec::new();
        for (k, &n) in sizes.iter().enumerate() {
            let colour = palette[k % palette.len()];
            for (solver, mark) in [("xpbd", Mark::Line), ("xpbd+tethers", Mark::Dashed)] {
                // In substep order (rows come that way): where more substeps cost less (1
                // and 2 substeps at 64² solve bending implicitly), the curve turns back.
                let line: Vec<(f64, f64)> = rows
                    .iter()
                    .filter(shown)
                    .filter(|r| r.1 == n && r.0 == solver)
                    .map(|r| (r.4.ms, f64::from(r.4.max_strain) * 100.0))
                    .collect();
                if line.is_empty() {
                    continue;
                }
                if let Mark::Dashed = mark {
                    chart.draw_series(DashedLineSeries::new(
                        line.clone(),
                        8,
                        5,
                        colour.stroke_width(2),
                    ))?;
                    chart.draw_series(line.iter().map(|&(x, y)| {
                        EmptyElement::at((x, y))
                            + Rectangle::new([(-4, -4), (4, 4)], colour.stroke_width(2))
                    }))?;
                    legend.push((format!("ours {n}x{n} + tethers"), mark, colour));
                } else {
                    chart.draw_series(LineSeries::new(line.clone(), colour.stroke_width(2)))?;
                    chart.draw_series(line.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
                    legend.push((format!("ours {n}x{n}"), mark, colour));
                }
            }
            let theirs: Vec<(f64, f64)> = peer
                .iter()
                .filter(|p| p.n == n)
                .map(|p| (p.ms, p.max_strain * 100.0))
                .collect();
            if !theirs.is_empty() {
                chart.draw_series(
                    theirs
                        .iter()
                        .map(|&p| TriangleMarker::new(p, 8, colour.filled())),
                )?;
                legend.push((format!("pypbd {n}x{n}"), Mark::Triangle, colour));
            }
        }
        let font = ("sans-serif", 16).into_font();
        legend_area.draw(&Text::new(
            "XPBD, 1 iteration, by substeps",
            (10, 40),
            font.clone(),
        ))?;
        for (i, (label, mark, colour)) in legend.iter().enumerate() {
            let y = 80 + 28 * i as i32;
            match mark {
                Mark::Line => {
                    legend_area.draw(&PathElement::new(
                        [(10, y), (40, y)],
                        colour.stroke_width(2),
                    ))?;
                    legend_area.draw(&Circle::new((25, y), 4, colour.filled()))?;
                }
                Mark::Dashed => {
                    for x in [10, 24, 38] {
                        legend_area.draw(&PathElement::new(
                            [(x, y), (x + 8, y)],
                            colour.stroke_width(2),
                        ))?;
                    }
                    legend_area.draw(&Rectangle::new(
                        [(21, y - 4), (29, y + 4)],
                        colour.stroke_width(2),
                    ))?;
                }
                Mark::Triangle => {
                    legend_area.draw(&TriangleMarker::new((25, y), 8, colour.filled()))?;
                }
            }
            legend_area.draw(&Text::new(label.as_str(), (52, y - 9), font.clone()))?;
        }
        root.present()?;
    }
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, w, h);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.write_header()?.write_image_data(&buffer)?;
    Ok(())
}

/// Median ms per frame of stepping all of `sims` together with [`step_many`] (best of
/// `repeat` runs of `frames` frames, fresh cloths each run).
fn time_many(
    make: impl Fn() -> Vec<Simulation>,
    frames: usize,
    repeat: usize,
    par: &Workers,
) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..repeat.max(1) {
        let mut sims = make();
        let mut times = Vec::with_capacity(frames);
        for _ in 0..frames {
            let mut items = ManyItem::each(&mut sims);
            let t = Instant::now();
            step_many(&mut items, DT, &Environment::default(), par);
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        times.drain(..WARMUP.min(frames / 2));
        times.sort_by(f64::total_cmp);
        best = best.min(times[times.len() / 2]);
    }
    best
}

/// `--many`: 64 cloths of 16² against one of 128² (the same vertex count), and one 128² with
/// 64 × 16² on all threads against one thread, all on the standard scene (XPBD 10 × 1).
fn many(args: &Args, par: &Workers, threads: usize, bending: Bending) {
    let frames = args.frames.unwrap_or(60) as usize;
    let repeat: usize = args.get("repeat", 3);
    let serial = Workers::new(0);
    let big = || vec![scene(128, "xpbd", 10, 1, bending)];
    let small = || (0..64).map(|_| scene(16, "xpbd", 10, 1, bending)).collect();
    let mixed = || {
        let mut v = big();
        v.extend(small());
        v
    };
    let one = time_many(big, frames, repeat, par);
    let sixty_four = time_many(small, frames, repeat, par);
    let mixed_all = time_many(mixed, frames, repeat, par);
    let mixed_one = time_many(mixed, frames, repeat, &serial);
    for (name, ms) in [
        ("one_128", one),
        ("64_of_16", sixty_four),
        ("128_and_64_of_16", mixed_all),
        ("128_and_64_of_16_one_thread", mixed_one),
    ] {
        println!(
            "{}",
            Json::default()
                .str("many", name)
                .num("ms_per_frame", (ms * 1e4).round() / 1e4)
                .num(
                    "threads",
                    if name.ends_with("one_thread") {
                        1
                    } else {
                        threads as u32
                    }
                )
        );
    }
    println!(
        "{}",
        Json::default()
            .str("summary", "many_cloths")
            .num("ratio_64_of_16_to_one_128", sixty_four / one)
            .num("mixed_speedup_all_threads", mixed_one / mixed_all)
    );
}

/// `--sleep`: what a cloth at rest costs. The standard scene with damping 2/s (it comes to
/// rest in seconds) and the default [`Sleep`]: the median awake step over its first frames
/// against the median step once it sleeps.
fn sleep_cost(args: &Args, par: &Workers, bending: Bending) {
    let frames = args.frames.unwrap_or(60) as usize;
    for n in list(args, "sizes", &[64u32, 256]) {
        let make = || {
            let mut sim = scene(n, "xpbd", 10, 1, bending);
            let params = SolverParams {
                damping: 2.0,
                sleep: Sleep::default(),
                ..*sim.params()
            };
            sim.set_params(params).unwrap();
            if args.rest.contains_key("tethers") {
                sim.set_features(Features {
                    tethers: Some(TetherParams::default()),
                    ..Default::default()
                })
                .unwrap();
            }
            sim
        };
        let median = |mut t: Vec<f64>| {
            t.sort_by(f64::total_cmp);
            t[t.len() / 2]
        };
        let mut sim = make();
        let mut awake = Vec::new();
        let mut steps = 0;
        while !sim.is_sleeping() && steps < 60 * 120 {
            let t = Instant::now();
            sim.step(DT, par);
            if steps >= WARMUP && awake.len() < frames {
                awake.push(t.elapsed().as_secs_f64() * 1e3);
            }
            steps += 1;
        }
        let asleep_ms = if sim.is_sleeping() {
            let times = (0..frames.max(100))
                .map(|_| {
                    let t = Instant::now();
                    sim.step(DT, par);
                    t.elapsed().as_secs_f64() * 1e3
                })
                .collect();
            median(times)
        } else {
            f64::NAN
        };
        let awake_ms = median(awake);
        println!(
            "{}",
            Json::default()
                .str(
                    "sleep",
                    if sim.is_sleeping() {
                        "asleep"
                    } else {
                        "never slept"
                    }
                )
                .num("n", n)
                .num("steps_to_sleep", steps as f64)
                .num("awake_ms_per_frame", (awake_ms * 1e4).round() / 1e4)
                .num("asleep_ms_per_frame", (asleep_ms * 1e6).round() / 1e6)
                .num("asleep_over_awake", asleep_ms / awake_ms)
        );
    }
}

fn main() {
    let args = Args::parse(include_str!("tradeoff.rs"));
    let quick = args.rest.contains_key("quick");
    let sizes: Vec<u32> = list(
        &args,
        "sizes",
        if quick {
            &[32, 64]
        } else {
            &[32, 64, 128, 256]
        },
    );
    let solvers: Vec<String> = list(
        &args,
        "solvers",
        &[
            "xpbd".to_string(),
            "xpbd+tethers".to_string(),
            "pbd".to_string(),
            "lab".to_string(),
        ],
    );
    let substeps: Option<Vec<u32>> = args
        .rest
        .get("substeps")
        .map(|_| list(&args, "substeps", &[]));
    let iterations: Option<Vec<u32>> = args
        .rest
        .get("iterations")
        .map(|_| list(&args, "iterations", &[]));
    let frames = args.frames.unwrap_or(60) as usize;
    let threads: usize = args.get(
        "threads",
        std::thread::available_parallelism().map_or(1, |n| n.get()),
    );
    let reference_substeps: u32 = args.get("reference-substeps", 100);
    let repeat: usize = args.get("repeat", 3);
    let bending = Bending::parse(&args);
    // The calling thread works too: threads − 1 helpers keep one thread per core (with
    // `--threads 1` there are none and parts run one after another). The same pool the
    // plugin steps on (`ClothWorkers`).
    let par = Workers::new(threads.saturating_sub(1));
    if args.rest.contains_key("scene-costs") {
        scene_costs(&args, &par, threads);
        return;
    }
    if args.rest.contains_key("sleep") {
        sleep_cost(&args, &par, bending);
        return;
    }
    if args.rest.get("backend").map(String::as_str) == Some("gpu") {
        gpu_table(&args, &par, bending);
        return;
    }
    if args.rest.contains_key("many") {
        many(&args, &par, threads, bending);
        return;
    }
    let mut rows: Vec<(String, u32, u32, u32, Outcome)> = Vec::new();
    let peer = args.rest.get("peer").cloned();
    let mut peer_points: Vec<PeerPoint> = Vec::new();

    for &n in &sizes {
        let reference = simulate(
            || scene(n, "xpbd", reference_substeps, 1, bending),
            frames,
            1,
            &par,
        );
        for name in &solvers {
            let (default_s, default_i): (&[u32], &[u32]) = match (name.as_str(), quick) {
                ("lab", true) => (&[1], &[32]),
                ("lab", false) => (&[1, 4], &[8, 32]),
                ("xpbd+tethers", _) => (&[5, 10, 20], &[1]),
                (_, true) => (&[5, 10, 20], &[1]),
                (_, false) => (&[1, 2, 5, 10, 20, 40], &[1, 3]),
            };
            for &s in substeps.as_deref().unwrap_or(default_s) {
                for &i in iterations.as_deref().unwrap_or(default_i) {
                    let mut out = simulate(|| scene(n, name, s, i, bending), frames, repeat, &par);
                    let (ref_mean, ref_max) =
                        position_distance(&out.positions, &reference.positions);
                    out.ref_mean = ref_mean;
                    println!(
                        "{}",
                        Json::default()
                            .str("solver", name)
                            .str("bending", bending.name())
                            .num("n", n)
                            .num("substeps", s)
                            .num("iterations", i)
                            .num("ms_per_frame", (out.ms * 1e4).round() / 1e4)
                            .num("max_strain", out.max_strain)
                            .num("mean_strain", out.mean_strain)
                            .num("ref_mean", ref_mean)
                            .num("ref_max", ref_max)
                            .num("nan_count", out.nan as f64)
                            .num("threads", threads as f64)
                    );
                    rows.push((name.clone(), n, s, i, out));
                }
            }
        }
        for budget in [1.0, 4.0, 16.0] {
            let best = rows
                .iter()
                // Without tethers (the budget table in `docs/performance.md` says so).
                .filter(|r| r.1 == n && r.4.ms <= budget && r.4.nan == 0)
                .filter(|r| !r.0.ends_with("+tethers"))
                .min_by(|a, b| a.4.max_strain.total_cmp(&b.4.max_strain));
            let mut j = Json::default()
                .str("summary", "lowest_max_strain_within_budget")
                .num("n", n)
                .num("budget_ms", budget);
            if let Some((name, _, s, i, out)) = best {
                j = j
                    .num("max_strain", out.max_strain)
                    .str("solver", name)
                    .num("substeps", *s)
                    .num("iterations", *i)
                    .num("ms_per_frame", (out.ms * 1e4).round() / 1e4);
            } else {
                j = j.str("solver", "none within budget");
            }
            println!("{j}");
        }
        if let Some(peer) = &peer {
            // The peer's curve: fewer points at the big sizes (256² takes ~0.5 s a frame).
            let peer_substeps: &[u32] = if n <= 64 {
                &[5, 10, 20, 40]
            } else if n <= 128 {
                &[5, 10, 20]
            } else {
                &[10]
            };
            for &s in peer_substeps {
                if let Some(p) = run_peer(peer, n, s, 1, frames, threads) {
                    if s == 10
                        && let Some(ours) = rows
                            .iter()
                            .find(|r| r.0 == "xpbd" && r.1 == n && r.2 == 10 && r.3 == 1)
                    {
                        let mut j = Json::default()
                            .str("summary", "against_peer_xpbd_10x1")
                            .num("n", n)
                            .num("ours_ms", (ours.4.ms * 1e4).round() / 1e4)
                            .num("peer_ms", p.ms)
                            .num("speed_ratio", p.ms / ours.4.ms)
                            .num("ours_max_strain", ours.4.max_strain)
                            .num("peer_max_strain", p.max_strain);
                        if let Some(t) = rows
                            .iter()
                            .find(|r| r.0 == "xpbd+tethers" && r.1 == n && r.2 == 10 && r.3 == 1)
                        {
                            j = j
                                .num("tethered_ms", (t.4.ms * 1e4).round() / 1e4)
                                .num("tethered_speed_ratio", p.ms / t.4.ms)
                                .num("tethered_max_strain", t.4.max_strain);
                        }
                        println!("{j}");
                    }
                    peer_points.push(p);
                }
            }
        }
    }
    if let Some(path) = args.rest.get("plot") {
        match draw_plot(path, &rows, &peer_points, threads) {
            Ok(()) => eprintln!("plot written to {path}"),
            Err(e) => {
                eprintln!("cannot draw the plot {path}: {e}");
                std::process::exit(1)
            }
        }
    }
    if args.rest.contains_key("markdown") && !peer_points.is_empty() {
        eprintln!(
            "| n | ours ms/frame | pypbd ms/frame | ratio | our max strain | pypbd max strain | ours + tethers: ms/frame | ratio | max strain |"
        );
        eprintln!("|---|---|---|---|---|---|---|---|---|");
        for p in peer_points
            .iter()
            .filter(|p| p.substeps == 10 && p.iterations == 1)
        {
            if let Some(o) = rows
                .iter()
                .find(|r| r.0 == "xpbd" && r.1 == p.n && r.2 == 10 && r.3 == 1)
            {
                let tethered = rows
                    .iter()
                    .find(|r| r.0 == "xpbd+tethers" && r.1 == p.n && r.2 == 10 && r.3 == 1)
                    .map_or("– | – | –".to_string(), |t| {
                        format!(
                            "{:.2} | {:.1}× | {:.1} %",
                            t.4.ms,
                            p.ms / t.4.ms,
                            t.4.max_strain * 100.0
                        )
                    });
                eprintln!(
                    "| {}² | {:.2} | {:.1} | {:.1}× | {:.1} % | {:.1} % | {tethered} |",
                    p.n,
                    o.4.ms,
                    p.ms,
                    p.ms / o.4.ms,
                    o.4.max_strain * 100.0,
                    p.max_strain * 100.0
                );
            }
        }
    }
    if args.rest.contains_key("markdown") {
        eprintln!(
            "| solver | n | substeps × iterations | ms/frame | max strain | mean strain | ref mean (mm) |"
        );
        eprintln!("|---|---|---|---|---|---|---|");
        for (name, n, s, i, o) in &rows {
            eprintln!(
                "| {name} | {n}² | {s} × {i} | {:.3} | {:.1} % | {:.2} % | {:.1} |",
                o.ms,
                o.max_strain * 100.0,
                o.mean_strain * 100.0,
                o.ref_mean * 1e3
            );
        }
    }
}

/// A wgpu device for `--backend gpu` (timestamp queries when the adapter has them).
fn gpu_device() -> Result<(wgpu::Adapter, wgpu::Device, wgpu::Queue, bool), String> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle());
    let adapter = bevy::tasks::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        ..Default::default()
    }))
    .map_err(|e| e.to_string())?;
    let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
    let (device, queue) = bevy::tasks::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_features: if timestamps {
            wgpu::Features::TIMESTAMP_QUERY
        } else {
            wgpu::Features::empty()
        },
        required_limits: adapter.limits(),
        ..Default::default()
    }))
    .map_err(|e| e.to_string())?;
    Ok((adapter, device, queue, timestamps))
}

/// What the GPU did with one scene.
struct GpuOutcome {
    wall_ms: f64,
    /// Median per frame of each stage's timestamped time (ms), when timestamps exist.
    stages: Vec<(GpuStage, f64)>,
    /// The largest max strain of any cloth.
    max_strain: f32,
    nan: usize,
    dispatches: DispatchCount,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// Runs `sims` (one world) for `frames` frames of one step on the GPU kernels.
fn simulate_gpu(
    gpu: &(wgpu::Device, wgpu::Queue, GpuKernels, bool),
    sims: &[Simulation],
    frames: usize,
) -> Result<GpuOutcome, String> {
    let (device, queue, kernels, timestamps) = gpu;
    let refs: Vec<&Simulation> = sims.iter().collect();
    let mut world = GpuWorld::new(device, queue, kernels, &refs).map_err(|e| e.0)?;
    let targets: Vec<Vec<Vec<Vec3>>> = sims
        .iter()
        .map(|s| vec![s.state().pins().iter().map(|p| p.target).collect()])
        .collect();
    const QUERIES: u32 = 4096;
    let queries = timestamps.then(|| {
        device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("tradeoff"),
            ty: wgpu::QueryType::Timestamp,
            count: QUERIES,
        })
    });
    let bytes = u64::from(QUERIES) * 8;
    let resolve = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("tradeoff_resolve"),
        size: bytes,
        usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("tradeoff_timestamps"),
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let period = f64::from(queue.get_timestamp_period()) * 1e-6;
    let mut walls = Vec::new();
    let mut per_stage: Vec<Vec<f64>> = vec![Vec::new(); GpuStage::ALL.len()];
    let mut ran = [false; GpuStage::ALL.len()];
    let mut dispatches = DispatchCount::default();
    for frame in 0..frames {
        world.prepare(
            device,
            queue,
            kernels,
            &GpuFrame::uniform(DT, 1, &[], &targets),
        );
        dispatches = world.dispatches(kernels);
        let mut encoder = device.create_command_encoder(&Default::default());
        let stages = match &queries {
            Some(q) => {
                let stages = world.record_profiled(&mut encoder, kernels, q);
                let used = 2 * stages.len() as u32;
                assert!(used <= QUERIES, "more passes than queries");
                encoder.resolve_query_set(q, 0..used, &resolve, 0);
                encoder.copy_buffer_to_buffer(&resolve, 0, &staging, 0, u64::from(used) * 8);
                stages
            }
            None => {
                world.record(&mut encoder, kernels);
                Vec::new()
            }
        };
        let t = Instant::now();
        queue.submit([encoder.finish()]);
        let _ = device.poll(wgpu::PollType::wait_indefinitely());
        let wall = t.elapsed().as_secs_f64() * 1e3;
        if !stages.is_empty() {
            staging.map_async(wgpu::MapMode::Read, .., |_| {});
            let _ = device.poll(wgpu::PollType::wait_indefinitely());
            let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&staging.get_mapped_range(..));
            staging.unmap();
            if frame >= WARMUP.min(frames / 2) {
                let mut sums = vec![0.0; GpuStage::ALL.len()];
                for (i, stage) in stages.iter().enumerate() {
                    let dt = ticks[2 * i + 1].saturating_sub(ticks[2 * i]) as f64 * period;
                    sums[*stage as usize] += dt;
                    ran[*stage as usize] = true;
                }
                for (all, s) in per_stage.iter_mut().zip(sums) {
                    all.push(s);
                }
            }
        }
        if frame >= WARMUP.min(frames / 2) {
            walls.push(wall);
        }
    }
    let mut max_strain = 0.0f32;
    let mut nan = 0;
    for (i, sim) in sims.iter().enumerate() {
        let (pos, vel) = world.read_state(device, queue, i);
        nan += pos.iter().chain(&vel).filter(|v| !v.is_finite()).count();
        let mut check = sim.clone();
        check.state_mut().positions.copy_from_slice(&pos);
        max_strain = max_strain.max(check.strain().max);
    }
    Ok(GpuOutcome {
        wall_ms: median(walls),
        stages: GpuStage::ALL
            .iter()
            .zip(per_stage)
            .filter(|(s, v)| ran[**s as usize] && !v.is_empty())
            .map(|(s, v)| (*s, median(v)))
            .collect(),
        max_strain,
        nan,
        dispatches,
    })
}

/// `--backend gpu`: CPU and GPU side by side on the standard scene, with and without
/// self-collision.
fn gpu_table(args: &Args, par: &Workers, bending: Bending) {
    let sizes: Vec<u32> = list(args, "sizes", &[64, 128, 256, 512]);
    let frames = args.frames.unwrap_or(60) as usize;
    let (adapter, device, queue, timestamps) = match gpu_device() {
        Ok(d) => d,
        Err(e) => {
            eprintln!("--backend gpu: no wgpu adapter ({e}); install mesa-vulkan-drivers");
            std::process::exit(1)
        }
    };
    let info = adapter.get_info();
    let software = info.device_type == wgpu::DeviceType::Cpu;
    eprintln!(
        "GPU: {} ({:?}, {:?}); timestamps: {timestamps}{}",
        info.name,
        info.backend,
        info.device_type,
        if software {
            " — a software adapter: these GPU figures check correctness, not speed"
        } else {
            ""
        }
    );
    let kernels = GpuKernels::new(&device);
    let gpu = (device, queue, kernels, timestamps);
    let mut table = Vec::new();
    // `--many`: 64 cloths of 32² and 16 of 64², one world each; otherwise one cloth a size.
    let cases: Vec<(String, u32, usize)> = if args.rest.contains_key("many") {
        vec![("64 × 32²".into(), 32, 64), ("16 × 64²".into(), 64, 16)]
    } else {
        sizes.iter().map(|&n| (format!("{n}²"), n, 1)).collect()
    };
    for (label, n, count) in cases {
        for self_collision in [false, true] {
            let make = || {
                let mut sim = scene(n, "xpbd", 10, 1, bending);
                if self_collision {
                    sim.set_features(Features {
                        // The edge length, as `--scene-costs` uses.
                        self_collision: Some(SelfCollision {
                            thickness: 1.0 / (n - 1) as f32,
                            friction: 0.2,
                        }),
                        ..Default::default()
                    })
                    .unwrap();
                }
                sim
            };
            let make_all = || (0..count).map(|_| make()).collect::<Vec<_>>();
            // Big CPU cases once: they take seconds. Every frame, so both strains are at the
            // same moment.
            let cpu_frames = frames;
            let cpu_repeat = if n >= 256 { 1 } else { 3 };
            let (cpu_ms, cpu_strain) = if count == 1 {
                let cpu = simulate(make, cpu_frames, cpu_repeat, par);
                (cpu.ms, cpu.max_strain)
            } else {
                let ms = time_many(make_all, cpu_frames, cpu_repeat, par);
                let mut sims = make_all();
                for _ in 0..cpu_frames {
                    step_many(
                        &mut ManyItem::each(&mut sims),
                        DT,
                        &Environment::default(),
                        par,
                    );
                }
                let strain = sims.iter().map(|s| s.strain().max).fold(0.0f32, f32::max);
                (ms, strain)
            };
            let gpu_out = simulate_gpu(&gpu, &make_all(), frames);
            let mut j = Json::default()
                .str("backend_table", "xpbd_10x1")
                .str("scene", &label)
                .num("n", n)
                .num("cloths", count as u32)
                .str("self_collision", if self_collision { "on" } else { "off" })
                .num("cpu_ms_per_frame", (cpu_ms * 1e4).round() / 1e4)
                .num("cpu_max_strain", cpu_strain)
                .str("adapter", &info.name)
                .str(
                    "adapter_kind",
                    if software { "software" } else { "hardware" },
                );
            match &gpu_out {
                Ok(g) => {
                    j = j
                        .num("gpu_wall_ms_per_frame", (g.wall_ms * 1e4).round() / 1e4)
                        .num("gpu_max_strain", g.max_strain)
                        .num("gpu_nan_count", g.nan as f64)
                        .num("gpu_dispatches_per_frame", g.dispatches.per_frame)
                        .num("gpu_dispatches_per_substep", g.dispatches.per_substep);
                    let total: f64 = g.stages.iter().map(|s| s.1).sum();
                    if !g.stages.is_empty() {
                        j = j.num("gpu_timestamp_ms_per_frame", (total * 1e4).round() / 1e4);
                    }
                    for (stage, ms) in &g.stages {
                        j = j.num(
                            &format!("gpu_{}_ms", stage.name()),
                            (ms * 1e4).round() / 1e4,
                        );
                    }
                }
                Err(why) => j = j.str("gpu", &format!("not on the GPU: {why}")),
            }
            println!("{j}");
            table.push((label.clone(), self_collision, cpu_ms, cpu_strain, gpu_out));
        }
    }
    if args.rest.contains_key("markdown") {
        eprintln!(
            "| scene | self-collision | CPU ms/frame | GPU wall ms/frame | GPU timestamps ms/frame | dispatches/frame (/substep) | CPU max strain | GPU max strain |"
        );
        eprintln!("|---|---|---|---|---|---|---|---|");
        for (label, sc, cpu_ms, cpu_strain, g) in &table {
            let (wall, ts, d, strain) = match g {
                Ok(g) => (
                    format!("{:.2}", g.wall_ms),
                    if g.stages.is_empty() {
                        "—".to_string()
                    } else {
                        format!("{:.2}", g.stages.iter().map(|s| s.1).sum::<f64>())
                    },
                    format!("{} ({})", g.dispatches.per_frame, g.dispatches.per_substep),
                    format!("{:.0} %", g.max_strain * 100.0),
                ),
                Err(_) => ("CPU only".into(), "—".into(), "—".into(), "—".into()),
            };
            eprintln!(
                "| {label} | {} | {cpu_ms:.2} | {wall} | {ts} | {d} | {:.0} % | {strain} |",
                if *sc { "on" } else { "off" },
                cpu_strain * 100.0
            );
        }
    }
}
