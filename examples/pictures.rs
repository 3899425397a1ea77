//! Renders the README's pictures offscreen (no window; llvmpipe is enough): the flag in
//! velvet from the front and from behind (blue velvet, gold lining), and velvet draped over a
//! ball.
//!
//! ```text
//! cargo run --release --example pictures -- --out docs
//! ```
//! Options: `--out DIR` (default `docs`), `--width N --height N` (default 960 × 600),
//! `--frames N` (simulated frames before the shot, default 200).

#[path = "support/shots.rs"]
mod shots;
#[path = "support/mod.rs"]
mod support;

use std::path::PathBuf;

use bevy::prelude::*;
use support::Args;

fn main() {
    let args = Args::parse();
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
        // Mean brightness: 0 would be a black (failed) picture.
        let mean = p.pixels().map(|c| c.iter().sum::<f32>() / 3.0).sum::<f32>()
            / (p.width * p.height) as f32;
        json = json.num(p.name, mean);
    }
    println!("{json}");
}
