//! The velvet BRDF's WGSL (`src/render/velvet_brdf.wgsl`, what the material's shader calls)
//! against its CPU twin (`bevy_cloth::render::brdf`), evaluated on a GPU adapter (llvmpipe in
//! CI) through a tiny compute shader.

mod common;

use bevy::math::Vec3;
use bevy_cloth::render::brdf::{VelvetBrdf, distribution};
use wgpu::util::DeviceExt;

const BRDF: &str = include_str!("../src/render/velvet_brdf.wgsl");

/// Each case: n, v, l, albedo, sheen (xyz of five vec4s) and (α, k_amp, F0) in the last.
const KERNEL: &str = r"
struct Case { n: vec4<f32>, v: vec4<f32>, l: vec4<f32>, albedo: vec4<f32>, sheen: vec4<f32>, p: vec4<f32> }
@group(0) @binding(0) var<storage, read> cases: array<Case>;
@group(0) @binding(1) var<storage, read_write> results: array<vec4<f32>>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&cases) { return; }
    let c = cases[i];
    let f = velvet_brdf(c.n.xyz, c.v.xyz, c.l.xyz, c.albedo.xyz, c.sheen.xyz, c.p.x, c.p.y, c.p.z);
    // w: the distribution alone at n·v, to compare D over its whole range as well.
    results[i] = vec4<f32>(f, velvet_distribution(dot(c.n.xyz, c.v.xyz), c.p.x, c.p.y));
}
";

type Case = [[f32; 4]; 6];

fn run_on_gpu(device: &wgpu::Device, queue: &wgpu::Queue, cases: &[Case]) -> Vec<[f32; 4]> {
    // `#define_import_path` is a naga_oil directive, not WGSL.
    let lib: String = BRDF
        .lines()
        .filter(|l| !l.trim_start().starts_with('#'))
        .collect::<Vec<_>>()
        .join("\n");
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("velvet_parity"),
        source: wgpu::ShaderSource::Wgsl(format!("{lib}\n{KERNEL}").into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("velvet_parity"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("cases"),
        contents: bytemuck::cast_slice(cases),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = (cases.len() * 16) as u64;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("results"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("staging"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: output.as_entire_binding(),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((cases.len() as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&output, 0, &staging, 0, size);
    queue.submit([encoder.finish()]);
    staging.map_async(wgpu::MapMode::Read, .., |r| r.expect("map_async"));
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    let out = bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(&staging.get_mapped_range(..));
    staging.unmap();
    out
}

fn dir(theta: f32, phi: f32) -> Vec3 {
    Vec3::new(
        theta.sin() * phi.cos(),
        theta.cos(),
        theta.sin() * phi.sin(),
    )
}

/// Directions over the whole sphere plus the edge cases (n·m = 1, n·l = 0, l = −v), and
/// parameters over their whole ranges.
fn cases() -> Vec<(Vec3, Vec3, Vec3, VelvetBrdf)> {
    let mut x: u32 = 0x2545_f491;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x as f32 / u32::MAX as f32
    };
    let mut out = Vec::new();
    for i in 0..4000 {
        let brdf = VelvetBrdf {
            albedo: Vec3::new(rnd(), rnd(), rnd()),
            sheen: Vec3::new(rnd(), rnd(), rnd()),
            alpha: 0.05 + 0.95 * rnd(),
            k_amp: 10.0 * rnd(),
            f0: rnd(),
        };
        let n = dir(
            rnd() * core::f32::consts::PI,
            rnd() * core::f32::consts::TAU,
        );
        let (v, l) = match i % 8 {
            0 => (n, n),                          // n·m = 1
            1 => (n, n.any_orthonormal_vector()), // n·l = 0
            2 => (
                dir(
                    rnd() * core::f32::consts::PI,
                    rnd() * core::f32::consts::TAU,
                ),
                -n,
            ), // light from behind
            3 => {
                let v = dir(
                    rnd() * core::f32::consts::PI,
                    rnd() * core::f32::consts::TAU,
                );
                (v, -v) // h undefined
            }
            _ => (
                dir(
                    rnd() * core::f32::consts::PI,
                    rnd() * core::f32::consts::TAU,
                ),
                dir(
                    rnd() * core::f32::consts::PI,
                    rnd() * core::f32::consts::TAU,
                ),
            ),
        };
        out.push((n, v, l, brdf));
    }
    out
}

#[test]
fn wgsl_velvet_matches_the_cpu_reference() {
    let Some((adapter, device, queue)) =
        common::gpu_or_skip("wgsl_velvet_matches_the_cpu_reference")
    else {
        return;
    };
    eprintln!("adapter: {:?}", adapter.get_info().name);
    let cases = cases();
    let packed: Vec<Case> = cases
        .iter()
        .map(|(n, v, l, b)| {
            [
                n.extend(0.0).to_array(),
                v.extend(0.0).to_array(),
                l.extend(0.0).to_array(),
                b.albedo.extend(0.0).to_array(),
                b.sheen.extend(0.0).to_array(),
                [b.alpha, b.k_amp, b.f0, 0.0],
            ]
        })
        .collect();
    let gpu = run_on_gpu(&device, &queue, &packed);
    assert_eq!(gpu.len(), cases.len());
    let (mut worst, mut lit) = (0.0f32, 0);
    for ((n, v, l, b), g) in cases.iter().zip(&gpu) {
        let cpu = b.eval(*n, *v, *l);
        let d = distribution(n.dot(*v), b.alpha, b.k_amp);
        let gf = Vec3::new(g[0], g[1], g[2]);
        assert!(
            gf.is_finite() && g[3].is_finite(),
            "GPU non-finite for {n} {v} {l} {b:?}: {g:?}"
        );
        // f32 transcendental functions differ by a few ulp between CPU and GPU; 1e-4 relative
        // (plus 1e-6 absolute) is far below anything visible and far above rounding.
        let err = (gf - cpu).abs().max_element() / cpu.max_element().max(1e-2);
        assert!(err < 1e-4, "{n} {v} {l} {b:?}: GPU {gf} CPU {cpu}");
        let err_d = (g[3] - d).abs() / d.max(1e-2);
        assert!(err_d < 1e-4, "D({}) GPU {} CPU {d}", n.dot(*v), g[3]);
        worst = worst.max(err).max(err_d);
        lit += usize::from(cpu.max_element() > 0.0);
    }
    // Both lit and unlit cases were compared.
    assert!(
        lit > 1000 && lit < cases.len(),
        "lit {lit} of {}",
        cases.len()
    );
    eprintln!("{} cases, worst relative difference {worst:e}", cases.len());
}
