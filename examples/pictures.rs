//! Renders the README's pictures offscreen (no window; llvmpipe is enough): the hero, an
//! animated PNG of the velvet flag in gusty wind, and the stills of the flag in velvet from
//! the front and from behind (blue velvet, gold lining) and of velvet draped over a ball.
//!
//! ```text
//! cargo run --release --example pictures -- --out docs
//! ```
//! Options: `--out DIR` (default `docs`), `--width N --height N` (stills, default 960 × 600),
//! `--frames N` (simulated frames before the shots, default 200), `--no-animation`.
//! The animation is `flag.png` in `DIR`: 48 frames, one every 3 simulated frames (20 per
//! second), 640 × 400, looping.

#[path = "support/shots.rs"]
mod shots;
#[path = "support/mod.rs"]
mod support;

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use bevy::prelude::*;
use support::Args;

/// Frames of the animation and simulated frames between them.
const ANIMATION_FRAMES: usize = 48;
const EVERY: u32 = 3;

/// Writes `frames` as a looping APNG, `fps` frames per second (RGB, alpha dropped).
fn write_apng(path: &Path, frames: &[shots::Picture], fps: u16) -> Result<(), png::EncodingError> {
    let (w, h) = (frames[0].width, frames[0].height);
    let mut encoder = png::Encoder::new(BufWriter::new(File::create(path)?), w, h);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::High);
    encoder.set_animated(frames.len() as u32, 0)?;
    encoder.set_frame_delay(1, fps)?;
    let mut writer = encoder.write_header()?;
    for frame in frames {
        let rgb: Vec<u8> = frame
            .rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        writer.write_image_data(&rgb)?;
    }
    writer.finish()
}

/// Mean brightness of a picture: 0 would be a black (failed) picture.
fn brightness(p: &shots::Picture) -> f32 {
    p.pixels().map(|c| c.iter().sum::<f32>() / 3.0).sum::<f32>() / (p.width * p.height) as f32
}

fn main() {
    let args = Args::parse(include_str!("pictures.rs"));
    let out = PathBuf::from(args.get("out", "docs".to_string()));
    let size = UVec2::new(args.get("width", 960), args.get("height", 600));
    let frames = args.frames.unwrap_or(200);
    let pictures = shots::render(
        size,
        frames,
        shots::velvet_scene,
        &shots::velvet_shots(),
        Some(&out),
    );
    let mut json = support::Json::default().str("example", "pictures");
    for p in &pictures {
        json = json.num(p.name, brightness(p));
    }
    if !args.get("no-animation", false) {
        // The front shot's camera, a step back so the whole flag stays in the frame.
        let shot = shots::Shot {
            name: "flag",
            eye: Vec3::new(-1.0, 2.4, 6.2),
            target: Vec3::new(1.5, 2.5, 0.0),
        };
        let animation = shots::render_animation(
            UVec2::new(640, 400),
            frames,
            shots::velvet_scene,
            &shot,
            ANIMATION_FRAMES,
            EVERY,
        );
        let path = out.join("flag.png");
        write_apng(&path, &animation, (60 / EVERY) as u16).expect("write the animation");
        // How much the picture changes from frame to frame: 0 would be a still flag.
        let change = animation
            .windows(2)
            .map(|w| {
                w[0].rgba
                    .iter()
                    .zip(&w[1].rgba)
                    .filter(|(a, b)| a.abs_diff(**b) > 8)
                    .count() as f32
                    / w[0].rgba.len() as f32
            })
            .sum::<f32>()
            / (animation.len() - 1) as f32;
        json = json
            .num("flag", brightness(&animation[0]))
            .num("flag_frame_change", change);
    }
    println!("{json}");
}
