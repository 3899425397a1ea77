// VelvetMaterial = ExtendedMaterial<StandardMaterial, VelvetExtension>: the forward fragment
// shader (src/render/mod.rs). Base-material inputs (base colour × texture × vertex colour,
// uv_transform, normal map through vertex tangents, occlusion texture + SSAO, emissive, alpha
// mode, fog flag) come from `pbr_input_from_standard_material`; the lighting is Bevy's light
// loop (apply_pbr_lighting in bevy_pbr 0.19 pbr_functions.wgsl) with the velvet BRDF in place
// of the standard one. Environment maps, light probes, lightmaps, clearcoat and transmission
// are not used by this material.

#import bevy_pbr::{
    pbr_fragment::pbr_input_from_standard_material,
    pbr_functions::{alpha_discard, main_pass_post_lighting_processing},
    pbr_types,
    forward_io::{VertexOutput, FragmentOutput},
    mesh_view_bindings as view_bindings,
    mesh_view_types,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    clustered_forward as clustering,
    shadows,
    lighting,
    ambient,
}
#import bevy_cloth::velvet_brdf::velvet_brdf

// Must match `VelvetUniform` (ShaderType) in Rust, field for field.
struct VelvetUniform {
    sheen_color: vec4<f32>,   // sheen tint (linear rgb)
    back_color: vec4<f32>,    // used on back faces when VELVET_FLAGS_BACK is set (linear rgba)
    alpha: f32,               // roughness α (clamped on the CPU)
    k_amp: f32,               // amplitude k_amp
    f0: f32,                  // reflectance at normal incidence
    flags: u32,
};

const VELVET_FLAGS_BACK: u32 = 1u;

@group(#{MATERIAL_BIND_GROUP}) @binding(100) var<uniform> velvet: VelvetUniform;
@group(#{MATERIAL_BIND_GROUP}) @binding(101) var velvet_back_texture: texture_2d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(102) var velvet_back_sampler: sampler;

fn velvet_lighting(in: pbr_types::PbrInput) -> vec4<f32> {
    let albedo = in.material.base_color.rgb;
    let sheen = velvet.sheen_color.rgb;
    let alpha = velvet.alpha;
    let k_amp = velvet.k_amp;
    let f0 = velvet.f0;
    let N = in.N;
    let V = in.V;
    let P = in.world_position.xyz;
    let receives_shadows = (in.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) != 0u;

    var direct = vec3<f32>(0.0);

    // View-space z (as apply_pbr_lighting): cluster slice + directional cascade selection.
    let view_z = dot(vec4<f32>(
        view_bindings::view.view_from_world[0].z,
        view_bindings::view.view_from_world[1].z,
        view_bindings::view.view_from_world[2].z,
        view_bindings::view.view_from_world[3].z
    ), in.world_position);
    let cluster_index = clustering::view_fragment_cluster_index(in.frag_coord.xy, view_z, in.is_orthographic);
    let ranges = clustering::unpack_clusterable_object_index_ranges(cluster_index);

    // Point and spot lights (clustered; the cluster lists point lights first, then spot
    // lights, in one range with the same data layout).
    for (var i: u32 = ranges.first_point_light_index_offset;
            i < ranges.first_reflection_probe_index_offset;
            i = i + 1u) {
        let is_spot = i >= ranges.first_spot_light_index_offset;
        let light_id = clustering::get_clusterable_object_id(i);
        let light = &view_bindings::clustered_lights.data[light_id];
        let to_light = (*light).position_radius.xyz - P;
        let d2 = dot(to_light, to_light);
        let L = to_light * inverseSqrt(max(d2, 1.0e-8));
        let NdotL = saturate(dot(N, L));
        // color_inverse_square_range.rgb = colour × intensity/(4π) (premultiplied on the CPU);
        // .w = 1/range² for the smooth range cut-off.
        var falloff = lighting::getDistanceAttenuation(d2, (*light).color_inverse_square_range.w);
        if is_spot {
            // Cone: direction stored as (x, z) + sign-of-y flag; scale/offset precomputed.
            var spot_dir = vec3<f32>((*light).light_custom_data.x, 0.0, (*light).light_custom_data.y);
            spot_dir.y = sqrt(max(0.0, 1.0 - spot_dir.x * spot_dir.x - spot_dir.z * spot_dir.z));
            if ((*light).flags & mesh_view_types::POINT_LIGHT_FLAGS_SPOT_LIGHT_Y_NEGATIVE) != 0u {
                spot_dir.y = -spot_dir.y;
            }
            let cone = saturate(dot(-spot_dir, L) * (*light).light_custom_data.z
                + (*light).light_custom_data.w);
            falloff = falloff * cone * cone;
        }
        var shadow = 1.0;
        if receives_shadows
                && ((*light).flags & mesh_view_types::POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            if is_spot {
                shadow = shadows::fetch_spot_shadow(
                    light_id, in.world_position, in.world_normal, (*light).shadow_map_near_z, in.frag_coord.xy);
            } else {
                shadow = shadows::fetch_point_shadow(light_id, in.world_position, in.world_normal, in.frag_coord.xy);
            }
        }
        direct += velvet_brdf(N, V, L, albedo, sheen, alpha, k_amp, f0) * NdotL
            * (*light).color_inverse_square_range.rgb * falloff * shadow;
    }

    // Directional lights (color.rgb = colour × illuminance).
    let n_directional_lights = view_bindings::lights.n_directional_lights;
    for (var i: u32 = 0u; i < n_directional_lights; i = i + 1u) {
        let light = &view_bindings::lights.directional_lights[i];
        let L = (*light).direction_to_light;
        let NdotL = saturate(dot(N, L));
        var shadow = 1.0;
        if receives_shadows
                && ((*light).flags & mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            shadow = shadows::fetch_directional_shadow(i, in.world_position, in.world_normal, view_z, in.frag_coord.xy);
        }
        direct += velvet_brdf(N, V, L, albedo, sheen, alpha, k_amp, f0) * NdotL * (*light).color.rgb * shadow;
    }

    // Ambient (AmbientLight on the camera, else GlobalAmbientLight): Bevy's split-sum
    // approximation with the velvet diffuse colour and F0 × sheen as the specular colour.
    let NdotV = max(dot(N, V), 0.0001);
    let indirect = ambient::ambient_light(
        in.world_position, N, V, NdotV,
        albedo * (1.0 - f0), sheen * f0, sqrt(saturate(alpha)), in.diffuse_occlusion);

    // Emissive (as apply_pbr_lighting): emissive.a is the exposure weight.
    let emissive = in.material.emissive;
    let emissive_light = emissive.rgb * in.material.base_color.a
        * mix(1.0, view_bindings::view.exposure, emissive.a);

    return vec4<f32>(
        view_bindings::view.exposure * (direct + indirect) + emissive_light,
        in.material.base_color.a);
}

@fragment
fn fragment(
    in: VertexOutput,
    @builtin(front_facing) is_front: bool,
) -> FragmentOutput {
    var pbr_input = pbr_input_from_standard_material(in, is_front);

    // Two-sided shading, independent of StandardMaterial::double_sided (Bevy does not flip
    // world_normal on back faces when VERTEX_TANGENTS is defined): the geometric normal faces
    // the viewer's side, and N is made to agree with it.
    let side = select(-1.0, 1.0, is_front);
    let geometric_n = in.world_normal * side;
    pbr_input.world_normal = geometric_n;
    pbr_input.N = select(-pbr_input.N, pbr_input.N, dot(pbr_input.N, geometric_n) >= 0.0);

    // Optional back colour / texture: sample unconditionally (derivatives need uniform control
    // flow), then choose. A `None` texture binds Bevy's white fallback image.
#ifdef VERTEX_UVS_A
    let uv = (pbr_input.material.uv_transform * vec3<f32>(in.uv, 1.0)).xy;
    let back_sample = textureSampleBias(velvet_back_texture, velvet_back_sampler, uv,
        view_bindings::view.mip_bias);
#else
    let back_sample = vec4<f32>(1.0);
#endif
    var back_color = velvet.back_color * back_sample;
#ifdef VERTEX_COLORS
    back_color = back_color * in.color;
#endif
    if !is_front && (velvet.flags & VELVET_FLAGS_BACK) != 0u {
        pbr_input.material.base_color = back_color;
    }

    pbr_input.material.base_color = alpha_discard(pbr_input.material, pbr_input.material.base_color);

    var out: FragmentOutput;
    if (pbr_input.material.flags & pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT) != 0u {
        out.color = pbr_input.material.base_color;
    } else {
        out.color = velvet_lighting(pbr_input);
    }
    // Fog (DISTANCE_FOG + material fog flag), tonemapping + deband (TONEMAP_IN_SHADER /
    // DEBAND_DITHER, non-HDR cameras), alpha premultiply (PREMULTIPLY_ALPHA).
    out.color = main_pass_post_lighting_processing(pbr_input, out.color);
    return out;
}
