//! The velvet cloth material (report §3.4) for any mesh, cloth or not.
//!
//! [`VelvetMaterial`] is a [`StandardMaterial`] extended with [`VelvetExtension`]: the base
//! material gives the base colour and texture, the normal map (through the per-vertex tangents
//! the solver writes), occlusion, emissive, alpha and fog; the extension replaces the lighting
//! with the velvet BRDF ([`brdf`]) for every directional, point and spot light (with their
//! shadows), ambient light, then Bevy's fog and tonemapping.
//!
//! **Two sides.** The report draws cloth in two passes — front faces culled back with the
//! vertex normal, back faces culled front with the normal flipped — so the two sides are lit
//! differently. [`VelvetMaterial`] does both passes in one draw with culling off: each
//! fragment knows which side it is on (`front_facing`), and a back-side fragment is shaded with
//! the flipped normal and, if set, [`VelvetExtension::back_color`] /
//! [`VelvetExtension::back_texture`]. Every pixel is shaded once (no double-darkening) from a
//! single depth write (no z-fighting), and the shadow pass is drawn with culling off too, so
//! the cloth casts shadows whichever side faces the light.
//!
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_cloth::render::{VelvetExtension, VelvetMaterial, VelvetPlugin, velvet_material};
//!
//! fn main() {
//!     App::new()
//!         .add_plugins((DefaultPlugins, VelvetPlugin))
//!         .add_systems(Startup, setup)
//!         .run();
//! }
//!
//! fn setup(
//!     mut commands: Commands,
//!     mut meshes: ResMut<Assets<Mesh>>,
//!     mut materials: ResMut<Assets<VelvetMaterial>>,
//! ) {
//!     let velvet = velvet_material(
//!         Color::srgb(0.35, 0.02, 0.08),
//!         VelvetExtension {
//!             back_color: Some(Color::srgb(0.8, 0.65, 0.3)),
//!             ..default()
//!         },
//!     );
//!     commands.spawn((
//!         Mesh3d(meshes.add(Sphere::new(1.0).mesh().uv(32, 18))),
//!         MeshMaterial3d(materials.add(velvet)),
//!     ));
//! }
//! ```

pub mod brdf;

use bevy::asset::{AssetPath, embedded_path};
use bevy::material::OpaqueRendererMethod;
use bevy::mesh::MeshVertexBufferLayoutRef;
use bevy::pbr::{
    ExtendedMaterial, MaterialExtension, MaterialExtensionKey, MaterialExtensionPipeline,
    MaterialPlugin, PbrPlugin,
};
use bevy::prelude::*;
use bevy::render::render_resource::{
    AsBindGroup, RenderPipelineDescriptor, ShaderType, SpecializedMeshPipelineError,
};
use bevy::shader::{ShaderRef, load_shader_library};

use brdf::{ALPHA_RANGE, F0_RANGE, K_AMP_RANGE, VelvetBrdf};

/// The velvet material: a [`StandardMaterial`] base plus the velvet lighting. Build one with
/// [`velvet_material`] (or [`velvet_material_from`] to start from your own base).
pub type VelvetMaterial = ExtendedMaterial<StandardMaterial, VelvetExtension>;

/// The velvet part of a [`VelvetMaterial`]: the BRDF's parameters and the optional back side.
///
/// Values outside their ranges are clamped by the shader (and by [`brdf::VelvetBrdf`]) and
/// reported once by [`VelvetPlugin`] with the material's handle.
#[derive(Asset, AsBindGroup, Reflect, Debug, Clone)]
#[uniform(100, VelvetUniform)]
pub struct VelvetExtension {
    /// Tint of the sheen (specular) lobe; white is the report's BRDF as written.
    pub sheen_color: Color,
    /// Roughness `α` of the sheen, in [`brdf::ALPHA_RANGE`] (0.05 … 1): small values give a
    /// thin bright rim at grazing angles, large ones a broad soft sheen.
    pub alpha: f32,
    /// Amplitude `k_amp` of the grazing peak, in [`brdf::K_AMP_RANGE`] (0 … 10; 4 in
    /// Ashikhmin's velvet, 0 turns the peak off).
    pub k_amp: f32,
    /// Reflectance at normal incidence `F0`, in [`brdf::F0_RANGE`] (0 … 1; fabrics ≈ 0.04).
    pub f0: f32,
    /// Colour of the back side. `None`: the back uses the base colour (lit with the flipped
    /// normal). Multiplied by [`Self::back_texture`] when both are set.
    pub back_color: Option<Color>,
    /// Texture of the back side (UV 0). Setting it alone uses it with a white back colour.
    #[texture(101)]
    #[sampler(102)]
    #[dependency]
    pub back_texture: Option<Handle<Image>>,
}

impl Default for VelvetExtension {
    fn default() -> Self {
        let b = VelvetBrdf::default();
        Self {
            sheen_color: Color::WHITE,
            alpha: b.alpha,
            k_amp: b.k_amp,
            f0: b.f0,
            back_color: None,
            back_texture: None,
        }
    }
}

/// A velvet parameter outside its range.
#[derive(Clone, Debug, PartialEq)]
pub struct VelvetParamError {
    /// The field's name.
    pub field: &'static str,
    /// The value given.
    pub value: f32,
    /// The range it must be in.
    pub range: core::ops::RangeInclusive<f32>,
}

impl core::fmt::Display for VelvetParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "velvet {} = {} is outside {}..={} (clamped)",
            self.field,
            self.value,
            self.range.start(),
            self.range.end()
        )
    }
}

impl std::error::Error for VelvetParamError {}

impl VelvetExtension {
    /// Checks every parameter against its range (NaN fails).
    ///
    /// # Errors
    /// The first parameter outside its range.
    pub fn validate(&self) -> Result<(), VelvetParamError> {
        for (field, value, range) in [
            ("alpha", self.alpha, ALPHA_RANGE),
            ("k_amp", self.k_amp, K_AMP_RANGE),
            ("f0", self.f0, F0_RANGE),
        ] {
            if !range.contains(&value) {
                return Err(VelvetParamError {
                    field,
                    value,
                    range,
                });
            }
        }
        Ok(())
    }

    /// The CPU BRDF with these parameters and `base_color` as the diffuse albedo: what the
    /// shader evaluates for a front-side fragment without textures.
    #[must_use]
    pub fn brdf(&self, base_color: Color) -> VelvetBrdf {
        VelvetBrdf {
            albedo: rgb(base_color),
            sheen: rgb(self.sheen_color),
            alpha: self.alpha,
            k_amp: self.k_amp,
            f0: self.f0,
        }
        .clamped()
    }
}

fn rgb(c: Color) -> Vec3 {
    c.to_linear().to_vec3()
}

/// Bit in [`VelvetUniform::flags`]: the back side has its own colour or texture.
pub const VELVET_FLAG_BACK: u32 = 1;

/// The extension's uniform as the shader reads it (binding 100): linear colours, parameters
/// already clamped to their ranges.
#[derive(Clone, Copy, Debug, Default, ShaderType)]
pub struct VelvetUniform {
    /// Sheen tint (linear RGB, `w` unused).
    pub sheen_color: Vec4,
    /// Back colour (linear RGBA; white when only a texture is set).
    pub back_color: Vec4,
    /// Roughness `α`.
    pub alpha: f32,
    /// Amplitude `k_amp`.
    pub k_amp: f32,
    /// `F0`.
    pub f0: f32,
    /// [`VELVET_FLAG_BACK`].
    pub flags: u32,
}

impl From<&VelvetExtension> for VelvetUniform {
    fn from(e: &VelvetExtension) -> Self {
        let b = e.brdf(Color::BLACK);
        let back = e.back_color.is_some() || e.back_texture.is_some();
        let back_color = e.back_color.unwrap_or(Color::WHITE).to_linear().to_vec4();
        Self {
            sheen_color: b.sheen.extend(1.0),
            back_color: back_color.clamp(Vec4::ZERO, Vec4::ONE),
            alpha: b.alpha,
            k_amp: b.k_amp,
            f0: b.f0,
            flags: if back { VELVET_FLAG_BACK } else { 0 },
        }
    }
}

impl MaterialExtension for VelvetExtension {
    fn fragment_shader() -> ShaderRef {
        ShaderRef::Path(
            AssetPath::from_path_buf(embedded_path!("velvet.wgsl")).with_source("embedded"),
        )
    }

    fn specialize(
        _pipeline: &MaterialExtensionPipeline,
        descriptor: &mut RenderPipelineDescriptor,
        _layout: &MeshVertexBufferLayoutRef,
        _key: MaterialExtensionKey<Self>,
    ) -> Result<(), SpecializedMeshPipelineError> {
        // Both sides in one draw (see the module docs); this runs for the shadow pass too.
        descriptor.primitive.cull_mode = None;
        Ok(())
    }
}

/// A velvet material with `base_color` as the diffuse albedo and the given velvet part.
#[must_use]
pub fn velvet_material(base_color: impl Into<Color>, velvet: VelvetExtension) -> VelvetMaterial {
    velvet_material_from(
        StandardMaterial {
            base_color: base_color.into(),
            ..default()
        },
        velvet,
    )
}

/// A lined cloth: velvet of `color` in front and a paler, warmer lining behind (the colour
/// mixed halfway with a cream), as the examples and the editor dress their cloths.
#[must_use]
pub fn lined_velvet(color: Color) -> VelvetMaterial {
    let lining = color.to_linear().mix(&LinearRgba::rgb(0.75, 0.7, 0.6), 0.5);
    velvet_material(
        color,
        VelvetExtension {
            back_color: Some(lining.into()),
            ..default()
        },
    )
}

/// A velvet material on your own `base` (base colour texture, normal map, occlusion,
/// emissive, alpha, fog, UV transform are used; roughness, metallic, reflectance and the
/// other lighting fields are replaced by the velvet BRDF). Culling is turned off and the
/// material is drawn in the forward pass (the deferred pass would light it as a standard
/// material); `double_sided` is cleared because the velvet shader flips back-face normals
/// itself.
#[must_use]
pub fn velvet_material_from(base: StandardMaterial, velvet: VelvetExtension) -> VelvetMaterial {
    ExtendedMaterial {
        base: StandardMaterial {
            cull_mode: None,
            double_sided: false,
            opaque_render_method: OpaqueRendererMethod::Forward,
            ..base
        },
        extension: velvet,
    }
}

/// Adds [`VelvetMaterial`]: its shaders and `MaterialPlugin::<VelvetMaterial>`. Needs Bevy's
/// PBR renderer (`DefaultPlugins`); in an app without it (a headless `MinimalPlugins` app) it
/// logs that and adds nothing, so the same plugin list works in tests.
pub struct VelvetPlugin;

impl Plugin for VelvetPlugin {
    fn build(&self, app: &mut App) {
        if !app.is_plugin_added::<PbrPlugin>() {
            warn!(
                "VelvetPlugin: no PbrPlugin in this app (a headless app, or VelvetPlugin added \
                 before DefaultPlugins); the velvet material is not available"
            );
            return;
        }
        load_shader_library!(app, "velvet_brdf.wgsl");
        load_shader_library!(app, "velvet.wgsl");
        app.add_plugins(MaterialPlugin::<VelvetMaterial>::default())
            .add_systems(PostUpdate, report_bad_velvet);
    }
}

/// Logs once per added or changed material each parameter outside its range.
fn report_bad_velvet(
    mut events: MessageReader<AssetEvent<VelvetMaterial>>,
    materials: Res<Assets<VelvetMaterial>>,
) {
    for event in events.read() {
        if let AssetEvent::Added { id } | AssetEvent::Modified { id } = event
            && let Some(m) = materials.get(*id)
            && let Err(e) = m.extension.validate()
        {
            error!("{id}: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_is_clamped_and_flags_the_back_side() {
        let u = VelvetUniform::from(&VelvetExtension {
            alpha: 7.0,
            k_amp: -1.0,
            f0: f32::NAN,
            sheen_color: Color::linear_rgb(2.0, 0.5, -1.0),
            ..default()
        });
        assert_eq!((u.alpha, u.k_amp, u.f0), (1.0, 0.0, 0.0));
        assert_eq!(u.sheen_color, Vec4::new(1.0, 0.5, 0.0, 1.0));
        assert_eq!(u.flags, 0);
        let u = VelvetUniform::from(&VelvetExtension {
            back_color: Some(Color::linear_rgb(0.25, 0.5, 1.0)),
            ..default()
        });
        assert_eq!(u.flags, VELVET_FLAG_BACK);
        assert_eq!(u.back_color, Vec4::new(0.25, 0.5, 1.0, 1.0));
    }

    #[test]
    fn validation_names_the_parameter() {
        assert!(VelvetExtension::default().validate().is_ok());
        let e = VelvetExtension {
            k_amp: 11.0,
            ..default()
        }
        .validate()
        .unwrap_err();
        assert_eq!(e.field, "k_amp");
        assert!(e.to_string().contains("k_amp = 11"), "{e}");
        let e = VelvetExtension {
            alpha: f32::NAN,
            ..default()
        }
        .validate()
        .unwrap_err();
        assert_eq!(e.field, "alpha");
    }

    #[test]
    fn materials_are_two_sided_and_forward() {
        let m = velvet_material(Color::WHITE, VelvetExtension::default());
        assert_eq!(m.base.cull_mode, None);
        assert!(!m.base.double_sided);
        assert_eq!(m.base.opaque_render_method, OpaqueRendererMethod::Forward);
    }
}
