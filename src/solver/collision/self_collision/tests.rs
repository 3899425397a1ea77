use super::*;
use crate::solver::parallel::{Serial, Workers};

/// The candidate lists of one step of 1/60 s, on one thread.
fn candidates(
    pos: &[Vec4],
    vel: &[Vec4],
    rest: &[Vec3],
    tris: &[[u32; 3]],
    params: SelfCollision,
) -> SelfCollisionScratch {
    let mut s = SelfCollisionScratch::default();
    find_self_collision_candidates(
        pos,
        vel,
        rest,
        tris,
        &[],
        params,
        1.0 / 60.0,
        &mut s,
        &Serial,
    );
    s
}

#[test]
fn close_vertices_are_pushed_apart_to_thickness() {
    let mut pos = vec![
        Vec4::new(0.0, 0.0, 0.0, 1.0),
        Vec4::new(0.0, 0.01, 0.0, 1.0),
        Vec4::new(5.0, 0.0, 0.0, 1.0),
    ];
    // They closed from 0.11 apart within the substep.
    let mut prev = pos.clone();
    prev[0].y = -0.05;
    prev[1].y = 0.06;
    let rest = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
    let params = SelfCollision {
        thickness: 0.1,
        friction: 0.0,
    };
    let mut s = candidates(&pos, &[Vec4::ZERO; 3], &rest, &[], params);
    self_collide(
        &mut pos,
        &mut prev,
        &[],
        Scales::default(),
        params,
        &mut s,
        &Serial,
    );
    assert!((pos[0].xyz().distance(pos[1].xyz()) - 0.1).abs() < 1e-6);
    assert_eq!(pos[2], prev[2]);
    // Equal masses: symmetric push.
    assert!((pos[0].y + 0.045).abs() < 1e-6 && (pos[1].y - 0.055).abs() < 1e-6);
}

/// Two vertices 0.01 apart, resting a metre apart, their thickness 0.1 without friction, and
/// their lists: a pair with an old overlap.
fn overlapping_pair() -> (Vec<Vec4>, SelfCollision, SelfCollisionScratch) {
    let start = vec![
        Vec4::new(0.0, 0.0, 0.0, 1.0),
        Vec4::new(0.0, 0.01, 0.0, 1.0),
    ];
    let rest = [Vec3::ZERO, Vec3::X];
    let params = SelfCollision {
        thickness: 0.1,
        friction: 0.0,
    };
    let s = candidates(&start, &[Vec4::ZERO; 2], &rest, &[], params);
    (start, params, s)
}

/// An overlap a pair already had when the substep began is undone by `DEPENETRATION`
/// thicknesses a substep, not at once; what the pair closed within the substep, at once.
#[test]
fn an_old_overlap_is_undone_a_little_each_substep() {
    let (start, params, mut s) = overlapping_pair();
    let step = DEPENETRATION * params.thickness;
    // One pass from `prev`; how far apart the two are after it.
    let mut pass = |pos: &mut Vec<Vec4>, prev: &[Vec4]| {
        let prev = &mut prev.to_vec();
        self_collide(pos, prev, &[], Scales::default(), params, &mut s, &Serial);
        pos[0].xyz().distance(pos[1].xyz())
    };
    let mut pos = start.clone();
    let apart = pass(&mut pos, &start);
    assert!((apart - (0.01 + step)).abs() < 1e-6, "{apart}");
    // Closing 0.02 within the next substep: that is undone, and another share.
    let prev = pos.clone();
    pos[1].y -= 0.02;
    let apart = pass(&mut pos, &prev);
    assert!((apart - (0.01 + 2.0 * step)).abs() < 1e-6, "{apart}");
    // What is left (0.02) is less than a share: apart to the thickness.
    let prev = pos.clone();
    let apart = pass(&mut pos, &prev);
    assert!((apart - 0.1).abs() < 1e-6, "{apart}");
}

/// What a pair pushes out of an overlap it began the substep with moves the positions at the
/// substep's start too: the two are put apart, not thrown apart. What they closed within the
/// substep is undone as a change of velocity, as before (an inelastic contact).
#[test]
fn a_pair_put_apart_from_an_old_overlap_gains_no_velocity() {
    let (start, params, mut s) = overlapping_pair();
    let step = DEPENETRATION * params.thickness;
    let mut pass = |pos: &mut [Vec4], prev: &mut [Vec4]| {
        self_collide(pos, prev, &[], Scales::default(), params, &mut s, &Serial);
    };
    let (mut pos, mut prev) = (start.clone(), start);
    pass(&mut pos, &mut prev);
    // Apart by a share of the thickness, each vertex by half of it, and no velocity.
    assert!((pos[0].y + 0.5 * step).abs() < 1e-6 && (pos[1].y - 0.01 - 0.5 * step).abs() < 1e-6);
    for (x, p) in pos.iter().zip(&prev) {
        assert!(x.distance(*p) < 1e-7, "{x} from {p}: a velocity");
    }
    // The upper one falls 0.02 onto the lower within the next substep: that is undone, and
    // another share; the two then move together at half its speed (momentum kept, nothing
    // bounces).
    let mut prev = pos.clone();
    pos[1].y -= 0.02;
    pass(&mut pos, &mut prev);
    let apart = pos[0].xyz().distance(pos[1].xyz());
    assert!((apart - (0.01 + 2.0 * step)).abs() < 1e-6, "{apart}");
    for (x, p) in pos.iter().zip(&prev) {
        assert!((x.y - p.y + 0.01).abs() < 1e-6, "{x} from {p}");
    }
}

#[test]
fn neighbours_resting_within_two_thicknesses_are_left_to_their_constraints() {
    let mut pos = vec![
        Vec4::new(0.0, 0.0, 0.0, 1.0),
        Vec4::new(0.05, 0.0, 0.0, 1.0),
    ];
    let prev = pos.clone();
    let rest = [Vec3::ZERO, Vec3::X * 0.05];
    let params = SelfCollision {
        thickness: 0.1,
        friction: 0.0,
    };
    let mut s = candidates(&pos, &[Vec4::ZERO; 2], &rest, &[], params);
    self_collide(
        &mut pos,
        &mut prev.clone(),
        &[],
        Scales::default(),
        params,
        &mut s,
        &Serial,
    );
    assert_eq!(pos, prev);
}

/// One pass of [`self_collide`] on one thread, every vertex at the cloth's thickness.
fn pass(
    pos: &mut [Vec4],
    prev: &[Vec4],
    tris: &[[u32; 3]],
    params: SelfCollision,
    s: &mut SelfCollisionScratch,
) {
    self_collide(
        pos,
        &mut prev.to_vec(),
        tris,
        Scales::default(),
        params,
        s,
        &Serial,
    );
}

#[test]
fn a_vertex_is_kept_on_its_side_of_a_triangle() {
    // A triangle in the XY plane and a vertex over it, far away along the cloth.
    let tri = [[0u32, 1, 2]];
    let rest = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z * 10.0];
    let params = SelfCollision {
        thickness: 0.1,
        friction: 0.0,
    };
    let start = vec![
        Vec4::new(0.0, 0.0, 0.0, 1.0),
        Vec4::new(1.0, 0.0, 0.0, 1.0),
        Vec4::new(0.0, 1.0, 0.0, 1.0),
        Vec4::new(0.25, 0.25, 0.02, 1.0),
    ];
    let mut s = candidates(&start, &[Vec4::ZERO; 4], &rest, &tri, params);
    assert_eq!(s.triangle_count[3], 1);
    assert_eq!(s.triangles[3 * MAX_SELF_TRIANGLES], SIDE_FRONT);
    // Come within the substep from 0.2 over it, too close on its side: pushed out along
    // +z, its share half the push (equal masses).
    let mut from = start.clone();
    from[3].z = 0.2;
    let mut pos = start.clone();
    pass(&mut pos, &from, &tri, params, &mut s);
    assert!((pos[3].z - 0.06).abs() < 1e-6, "{}", pos[3]);
    // Went through during the substep: brought back to its side.
    let mut pos = start.clone();
    pos[3].z = -0.05;
    pass(&mut pos, &from, &tri, params, &mut s);
    assert!((pos[3].z - (-0.05 + 0.075)).abs() < 1e-6, "{}", pos[3]);
    // Too close since before the substep: pushed out by DEPENETRATION thicknesses.
    let mut pos = start.clone();
    pass(&mut pos, &start, &tri, params, &mut s);
    let push = 0.5 * DEPENETRATION * params.thickness;
    assert!((pos[3].z - (0.02 + push)).abs() < 1e-6, "{}", pos[3]);
    // The triangle takes the reaction at its corners, by their weights at the point under
    // the vertex (0.5, 0.25, 0.25; equal masses): the contact moves no momentum.
    for (k, b) in [0.5, 0.25, 0.25].into_iter().enumerate() {
        let moved = pos[k] - start[k];
        assert!(
            (moved.z + push * b).abs() < 1e-6 && moved.x == 0.0 && moved.y == 0.0,
            "corner {k} moved by {moved}"
        );
    }
    let momentum: f32 = pos.iter().zip(&start).map(|(p, s)| (p.z - s.z) / p.w).sum();
    assert!(momentum.abs() < 1e-6, "{momentum}");
}

/// A vertex that came over a triangle within the step (beside it when the lists were made)
/// is stopped by it, but the triangle takes no reaction: with it, crumpled cloths of
/// uneven edges ended tangled more often (docs/experiments.md).
#[test]
fn a_triangle_the_vertex_came_over_within_the_step_takes_no_reaction() {
    let tri = [[0u32, 1, 2]];
    let rest = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z * 10.0];
    let params = SelfCollision {
        thickness: 0.1,
        friction: 0.0,
    };
    // Beside the triangle when the lists are made, moving over it.
    let mut start = vec![
        Vec4::new(0.0, 0.0, 0.0, 1.0),
        Vec4::new(1.0, 0.0, 0.0, 1.0),
        Vec4::new(0.0, 1.0, 0.0, 1.0),
        Vec4::new(-0.05, 0.25, 0.05, 1.0),
    ];
    let vel = [
        Vec4::ZERO,
        Vec4::ZERO,
        Vec4::ZERO,
        Vec4::new(6.0, 0.0, 0.0, 0.0),
    ];
    let mut s = candidates(&start, &vel, &rest, &tri, params);
    assert_eq!(s.triangle_count[3], 1);
    assert_ne!(s.triangles[3 * MAX_SELF_TRIANGLES] & BESIDE, 0);
    start[3].x = 0.25;
    let mut pos = start.clone();
    pass(&mut pos, &start, &tri, params, &mut s);
    assert!(pos[3].z > 0.05, "the vertex is pushed off: {}", pos[3]);
    assert_eq!(&pos[..3], &start[..3]);
}

/// A 5 × 5 sheet in the XY plane, 0.1 apart, its triangles and rest positions.
fn sheet() -> (Vec<Vec4>, Vec<Vec3>, Vec<[u32; 3]>) {
    let rest: Vec<Vec3> = (0..25)
        .map(|k| Vec3::new((k % 5) as f32 * 0.1, (k / 5) as f32 * 0.1, 0.0))
        .collect();
    let mut tris = Vec::new();
    for y in 0..4u32 {
        for x in 0..4u32 {
            let k = y * 5 + x;
            tris.push([k, k + 1, k + 6]);
            tris.push([k, k + 6, k + 5]);
        }
    }
    (rest.iter().map(|p| p.extend(1.0)).collect(), rest, tris)
}

#[test]
fn the_own_neighbourhood_is_looked_at_only_where_it_folded() {
    let (pos, rest, tris) = sheet();
    let params = SelfCollision {
        thickness: 0.1,
        friction: 0.0,
    };
    let lists = |pos: &[Vec4], vel: &[Vec4]| {
        let s = candidates(pos, vel, &rest, &tris, params);
        let count = s.triangle_count[12] as usize;
        s.triangles[12 * MAX_SELF_TRIANGLES..12 * MAX_SELF_TRIANGLES + count].to_vec()
    };
    // The middle vertex leaves the flat sheet fast along its normal: fast enough to slide
    // over the triangles beside it (within a thickness), but the sheet around it only
    // stretches, so none of them is looked at.
    let mut vel = vec![Vec4::ZERO; 25];
    vel[12] = Vec4::new(0.0, 0.0, 3.0, 0.0);
    assert_eq!(lists(&pos, &vel), Vec::<u32>::new());
    // The same with a vertex two edges away come 10 % closer (the sheet folds between
    // them): the triangles beside it that it can slide over are.
    let mut folded = pos.clone();
    folded[14].x -= 0.02;
    let found = lists(&folded, &vel);
    assert!(!found.is_empty());
    assert!(found.iter().all(|s| s & 3 == SIDE_FREE), "{found:?}");
    // Or the same vertex coming that close within two steps at its velocity (rising with
    // the middle one).
    let mut closing = vel.clone();
    closing[14] = Vec4::new(-0.6, 0.0, 3.0, 0.0);
    let ahead = lists(&pos, &closing);
    assert!(!ahead.is_empty());
    assert!(ahead.iter().all(|s| s & 3 == SIDE_FREE), "{ahead:?}");
    // Only just not: 2 % closer within two steps.
    closing[14].x = -0.12;
    assert_eq!(lists(&pos, &closing), Vec::<u32>::new());
}

/// The grid finds every neighbour brute force finds, wherever the vertices are: a pile
/// around the origin, around a point 10⁹ m out (cells beyond what an `i32`
/// counts), two vertices alone (fewer buckets than a row has cells) and non-finite ones.
#[test]
fn the_grid_finds_what_brute_force_finds() {
    let mut seed = 7u32;
    let mut next = move || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32
    };
    let params = SelfCollision {
        thickness: 0.05,
        friction: 0.0,
    };
    for (n, at) in [(400, Vec3::ZERO), (400, Vec3::splat(1e9)), (2, Vec3::ZERO)] {
        let spread = if n == 2 { 0.04 } else { 0.3 };
        let mut pos: Vec<Vec4> = (0..n)
            .map(|_| (at + Vec3::new(next(), next(), next()) * spread).extend(1.0))
            .collect();
        if n > 2 {
            pos[3].x = f32::NAN;
            pos[5].y = f32::INFINITY;
        }
        // Rest far apart: every pair can be neighbours.
        let rest: Vec<Vec3> = (0..n).map(|k| Vec3::X * k as f32).collect();
        let vel = vec![Vec4::ZERO; n];
        let s = candidates(&pos, &vel, &rest, &[], params);
        let reach = params.thickness;
        let mut total = 0;
        for i in 0..n {
            let p = pos[i].xyz();
            let mut want: Vec<u32> = (0..n)
                .filter(|&j| {
                    j != i
                        && p.is_finite()
                        && pos[j].xyz().is_finite()
                        && (pos[j].xyz() - p).length_squared() < reach * reach
                })
                .map(|j| j as u32)
                .collect();
            want.truncate(MAX_SELF_NEIGHBOURS);
            let count = s.neighbour_count[i] as usize;
            let got = &s.neighbours[i * MAX_SELF_NEIGHBOURS..i * MAX_SELF_NEIGHBOURS + count];
            assert_eq!(got, &want[..], "vertex {i} of {n} at {at}");
            total += count;
        }
        assert!(total > 0, "{n} at {at}: no pairs to compare");
    }
}

/// The own neighbourhood's groups of entries kept from the walk give the lists a second
/// walk gives, in a sheet crumpled to half its size (folded everywhere) with a thickness
/// of three edges (some vertices see more than [`NEAR_GROUPS`] groups of their own
/// neighbourhood, and take the second walk either way).
/// A 40 × 40 sheet crumpled to half its size, its velocities random, and a thickness of
/// three edges.
#[expect(clippy::type_complexity)]
fn crumpled_sheet() -> (
    Vec<Vec4>,
    Vec<Vec4>,
    Vec<Vec3>,
    Vec<[u32; 3]>,
    SelfCollision,
) {
    let mut seed = 11u32;
    let mut next = move || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
    };
    let side = 40;
    let h = 0.01;
    let at = |i: usize| Vec3::new((i % side) as f32, (i / side) as f32, 0.0) * h;
    let rest: Vec<Vec3> = (0..side * side).map(at).collect();
    let pos: Vec<Vec4> = rest
        .iter()
        .map(|r| (*r * 0.5 + Vec3::new(next(), next(), next()) * h).extend(1.0))
        .collect();
    let vel: Vec<Vec4> = (0..pos.len())
        .map(|_| Vec3::new(next(), next(), next()).extend(0.0))
        .collect();
    let mut tris = Vec::new();
    for y in 0..side - 1 {
        for x in 0..side - 1 {
            let i = (y * side + x) as u32;
            let s = side as u32;
            tris.push([i, i + 1, i + s + 1]);
            tris.push([i, i + s + 1, i + s]);
        }
    }
    let params = SelfCollision {
        thickness: 3.0 * h,
        friction: 0.0,
    };
    (pos, vel, rest, tris, params)
}

#[test]
fn the_kept_groups_find_what_a_second_walk_finds() {
    let (pos, vel, rest, tris, params) = crumpled_sheet();
    let dt = 1.0 / 60.0;
    let motion = motion_margin(&vel, params, dt, &Serial).unwrap();
    let t = params.thickness;
    let mut kept = SelfCollisionScratch::default();
    kept.find::<false>(&pos, &vel, dt, &rest, &tris, &[], t, motion, &Serial);
    let mut walked = SelfCollisionScratch::default();
    walked.find::<true>(&pos, &vel, dt, &rest, &tris, &[], t, motion, &Serial);
    assert_eq!(kept.neighbour_count, walked.neighbour_count);
    assert_eq!(kept.triangle_count, walked.triangle_count);
    let mut found = 0;
    for (i, &count) in kept.triangle_count.iter().enumerate() {
        let slots = i * MAX_SELF_TRIANGLES..i * MAX_SELF_TRIANGLES + count as usize;
        assert_eq!(
            kept.triangles[slots.clone()],
            walked.triangles[slots],
            "vertex {i}"
        );
        found += count;
    }
    assert!(
        found > 1000,
        "only {found} triangles found: the sheet did not fold"
    );
}

/// The own neighbourhood's triangles are first tested against a bound on how far the vertex
/// can slide within the step (from the speeds of the triangles' first corners and of the
/// corners around them); the lists are those of the bound by the whole margin, in a crumpled
/// sheet whose vertices move at random speeds from a hundredth of a thickness a step to
/// several (so the slides lie on both sides of what the bound cuts off).
#[test]
fn the_slide_bound_leaves_out_no_triangle_the_margin_keeps() {
    let (pos, vel, rest, tris, params) = crumpled_sheet();
    let dt = 1.0 / 60.0;
    let t = params.thickness;
    let mut found = 0;
    for scale in [0.02f32, 0.3, 1.0, 3.0, 20.0] {
        let vel: Vec<Vec4> = vel.iter().map(|v| *v * scale).collect();
        let motion = motion_margin(&vel, params, dt, &Serial).unwrap();
        let mut bound = SelfCollisionScratch::default();
        bound.find::<false>(&pos, &vel, dt, &rest, &tris, &[], t, motion, &Serial);
        let mut margin = SelfCollisionScratch {
            margin_slides: true,
            ..SelfCollisionScratch::default()
        };
        margin.find::<false>(&pos, &vel, dt, &rest, &tris, &[], t, motion, &Serial);
        let differ = (0..pos.len())
            .filter(|&i| {
                let slots = i * MAX_SELF_TRIANGLES..(i + 1) * MAX_SELF_TRIANGLES;
                bound.triangle_count[i] != margin.triangle_count[i]
                    || bound.triangles[slots.clone()] != margin.triangles[slots]
            })
            .count();
        assert_eq!(differ, 0, "speeds × {scale}: vertices whose lists differ");
        found += bound.triangle_count.iter().sum::<u32>();
    }
    assert!(found > 5000, "only {found} triangles found");
}

/// The lists kept from one mesh (triangles by first corner, longest edge) are rebuilt for
/// another: a scratch that stepped the whole sheet, then the sheet with half its triangles
/// gone (as after a tear), finds what a fresh scratch finds.
#[test]
fn a_scratch_stepping_another_mesh_finds_what_a_fresh_one_finds() {
    let (pos, vel, rest, tris, params) = crumpled_sheet();
    let dt = 1.0 / 60.0;
    let mut reused = candidates(&pos, &vel, &rest, &tris, params);
    let whole = reused.triangle_count.clone();
    let torn = &tris[tris.len() / 2..];
    find_self_collision_candidates(
        &pos,
        &vel,
        &rest,
        torn,
        &[],
        params,
        dt,
        &mut reused,
        &Serial,
    );
    let fresh = candidates(&pos, &vel, &rest, torn, params);
    assert_ne!(
        reused.triangle_count, whole,
        "the torn sheet found the same triangles"
    );
    assert_eq!(reused.neighbour_count, fresh.neighbour_count);
    assert_eq!(reused.triangle_count, fresh.triangle_count);
    for (i, &count) in fresh.triangle_count.iter().enumerate() {
        let slots = i * MAX_SELF_TRIANGLES..i * MAX_SELF_TRIANGLES + count as usize;
        assert_eq!(
            reused.triangles[slots.clone()],
            fresh.triangles[slots],
            "vertex {i}"
        );
    }
}

#[test]
fn the_grid_sorts_every_vertex_into_its_bucket_whatever_the_threads() {
    // Three runs of the sort, a few positions not finite, cells of a few vertices each.
    let n = 2 * SORT_RUN + 1000;
    let mut seed = 11u32;
    let mut next = move || {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (seed >> 8) as f32 / (1u32 << 24) as f32
    };
    let mut pos: Vec<Vec4> = (0..n)
        .map(|_| Vec3::new(next(), next(), next()).extend(1.0))
        .collect();
    // Some equal x in a bucket: vertex order decides.
    for k in (100..200).step_by(10) {
        pos[k + 5] = pos[k] + Vec4::new(0.0, 0.001, 0.0, 0.0);
    }
    for k in [0, 17, SORT_RUN, n - 1] {
        pos[k].y = f32::NAN;
    }
    let vel = vec![Vec4::ZERO; n];
    let rest = vec![Vec3::ZERO; n];
    let fill = |par: &dyn Fn(&mut Grid)| {
        let mut g = Grid::default();
        par(&mut g);
        g
    };
    let serial = fill(&|g| g.fill(&pos, &vel, &rest, 0.0, 0.05, &Serial));
    let pool = Workers::new(3);
    let threaded = fill(&|g| g.fill(&pos, &vel, &rest, 0.0, 0.05, &pool));
    assert_eq!(serial, threaded);
    let g = serial;
    let size = g.start.len() - 1;
    let real = g.start[size] as usize;
    assert_eq!(real, n - 4);
    let mut seen = vec![false; n];
    for h in 0..size {
        let bucket = &g.entries[g.start[h] as usize..g.start[h + 1] as usize];
        assert!(bucket.windows(2).all(|w| w[0] < w[1]), "ordered by vertex");
        for (k, &j) in bucket.iter().enumerate() {
            let j = j as usize;
            let c = cell_of(
                pos[j].xyz(),
                Vec3::new(1.0 / (0.05 * X_CELL), 1.0 / 0.05, 1.0 / 0.05),
            );
            assert_eq!(grid_bucket(c, size - 1), h, "vertex {j}");
            assert_eq!(g.cells[g.start[h] as usize + k], c);
            assert!(!std::mem::replace(&mut seen[j], true), "vertex {j} twice");
        }
    }
    assert_eq!(seen.iter().filter(|&&s| s).count(), n - 4);
}

#[test]
fn same_compares_every_run() {
    let pool = Workers::new(2);
    let a: Vec<u32> = (0..3 * 4 * CHUNK as u32 + 5).collect();
    let mut b = a.clone();
    assert!(same(&a, &b, &pool) && same(&a, &b, &Serial));
    *b.last_mut().unwrap() += 1;
    assert!(!same(&a, &b, &pool) && !same(&a, &b, &Serial));
    assert!(!same(&a, &a[1..], &pool));
    assert!(same::<u32>(&[], &[], &pool));
}

#[test]
fn listed_triangles_rank_in_triangle_order() {
    let members = [0usize, 5, 31, 32, 33, 64, 100, 127];
    let words: Vec<AtomicU32> = (0..4).map(|_| AtomicU32::new(0)).collect();
    // Marked out of order and twice, as the query's threads do.
    for &t in members.iter().rev().chain(&members) {
        Listed::mark(&words, t);
    }
    Listed::mark(&words, 128); // past the set: ignored
    let mut listed = Listed::default();
    listed.set(words);
    for t in 0..130 {
        let expected = members.iter().position(|&m| m == t);
        assert_eq!(listed.rank(t), expected, "triangle {t}");
    }
    assert_eq!(listed.before.last(), Some(&(members.len() as u32)));
}

/// Nearby cells spread over the buckets as if at random: a block of 16³ cells into twice as
/// many buckets, and the rows of a block of 64² into a table a query's rows read runs of. The
/// xor of the coordinates times odd constants (the hash before) put 2.5 to 3 times as many
/// of them into shared buckets as chance does.
#[test]
fn the_hashes_spread_nearby_cells() {
    let cells: Vec<IVec3> = (-8..8)
        .flat_map(|x| (-8..8).flat_map(move |y| (-8..8).map(move |z| IVec3::new(x, y, z))))
        .collect();
    let size = 2 * cells.len();
    let mut used = vec![false; size];
    let shared = cells
        .iter()
        .filter(|&&c| std::mem::replace(&mut used[hash(c, size)], true))
        .count();
    // By chance: k − m (1 − (1 − 1/m)^k) of k cells in m buckets, 873 here.
    let k = cells.len() as f64;
    let m = size as f64;
    let chance = k - m * (1.0 - (1.0 - 1.0 / m).powf(k));
    assert!(
        (shared as f64) < 1.15 * chance,
        "{shared} cells in shared buckets, chance {chance}"
    );
    // Rows: how many start within 4 buckets of another row's start (a query reads about
    // that many of a row's buckets at a time), against chance.
    let size = 1usize << 17;
    let mut starts: Vec<usize> = (-32..32)
        .flat_map(|y| (-32..32).map(move |z| row_base(y, z) & (size - 1)))
        .collect();
    starts.sort_unstable();
    let close = starts.windows(2).filter(|w| w[1] - w[0] < 4).count();
    let chance = (starts.len() * starts.len() * 4) as f64 / size as f64;
    assert!(
        (close as f64) < 1.3 * chance,
        "{close} rows close to another, chance {chance}"
    );
}

#[test]
fn cell_of_is_floor() {
    for x in [-2.5f32, -1.0, -0.5, 0.0, 0.5, 1.0, 2.5, -0.0001] {
        let c = cell_of(Vec3::new(x, -x, x * 3.0), Vec3::ONE);
        assert_eq!(
            c,
            IVec3::new(
                x.floor() as i32,
                (-x).floor() as i32,
                (x * 3.0).floor() as i32
            ),
            "{x}"
        );
    }
    // Beyond i32's range the cast saturates; the step down must not overflow.
    let far = cell_of(Vec3::new(-1e12, 1e12, -3.5e9), Vec3::ONE);
    assert_eq!(far.y, i32::MAX);
    assert!(far.x == i32::MIN || far.x == i32::MAX, "{far}");
}

#[test]
fn crossings_are_counted() {
    // A triangle in the XY plane and an edge through it along z, and one beside it.
    let pos: Vec<Vec4> = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.2, 0.2, -1.0),
        Vec3::new(0.2, 0.2, 1.0),
        Vec3::new(2.0, 2.0, -1.0),
        Vec3::new(2.0, 2.0, 1.0),
    ]
    .iter()
    .map(|p| p.extend(1.0))
    .collect();
    let tris = [[0, 1, 2]];
    assert_eq!(count_self_crossings(&pos, &tris, &[[3, 4], [5, 6]]), 1);
    // Edges touching the triangle's own vertices never count.
    assert_eq!(count_self_crossings(&pos, &tris, &[[0, 4]]), 0);
}

/// The grid's count against every edge tested with every triangle, on crumpled sheets and
/// triangle soups (some with coincident and far-off vertices): the same number each time,
/// and crossings in most of them (so the comparison has something to count).
#[test]
fn crossings_counted_through_the_grid_are_all_the_crossing_pairs() {
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut with_crossings = 0;
    for case in 0..24 {
        let (pos, tris): (Vec<Vec4>, Vec<[u32; 3]>) = if case % 2 == 0 {
            // A 12 × 12 sheet, each vertex moved at random by up to `amp` edges along every
            // axis: folds through itself from about half an edge on.
            let amp = 0.2 + case as f32 * 0.06;
            let grid = crate::solver::mesh::Grid::new(12, 12, 1.0, 1.0);
            let mut jitter = || (next() - 0.5) * amp / 11.0;
            let pos = grid
                .positions()
                .iter()
                .map(|p| (*p + Vec3::new(jitter(), jitter(), jitter())).extend(1.0))
                .collect();
            let tris = grid
                .indices()
                .chunks(3)
                .map(|t| [t[0], t[1], t[2]])
                .collect();
            (pos, tris)
        } else {
            // 80 small triangles (corners within 0.25 of a centre) in a 3 m box, every
            // fourth sharing a corner with the one before.
            let mut pos: Vec<Vec4> = Vec::new();
            let mut tris = Vec::new();
            for t in 0..80u32 {
                let c = Vec3::new(next(), next(), next()) * 3.0;
                let mut corner = || {
                    pos.push((c + (Vec3::new(next(), next(), next()) - 0.5) * 0.5).extend(1.0));
                    pos.len() as u32 - 1
                };
                let (a, b, d) = (corner(), corner(), corner());
                let a = if t % 4 == 3 { a - 3 } else { a };
                tris.push([a, b, d]);
            }
            (pos, tris)
        };
        let mut edges: Vec<[u32; 2]> = tris
            .iter()
            .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        let p = |i: u32| pos[i as usize].xyz();
        let brute = edges
            .iter()
            .map(|e| {
                tris.iter()
                    .filter(|t| !(t.contains(&e[0]) || t.contains(&e[1])))
                    .filter(|t| crossings::segment_crosses_triangle(p(e[0]), p(e[1]), t.map(p)))
                    .count()
            })
            .sum::<usize>();
        assert_eq!(
            count_self_crossings(&pos, &tris, &edges),
            brute,
            "case {case}"
        );
        with_crossings += usize::from(brute > 0);
    }
    assert!(
        with_crossings >= 12,
        "only {with_crossings} of 24 cases cross"
    );
}

/// The query's and the pass's chunks: 512 vertices on one thread; on several, enough chunks
/// for every thread to take about four (within 64 to 512 vertices a chunk), so a cloth of a
/// few hundred vertices is shared out and a big one is cut as before.
#[test]
fn self_collision_chunks_follow_the_threads_within_64_to_512_vertices() {
    for n in [1, 63, 100, 576, 1089, 4096, 9216, 65_536, 1 << 20] {
        assert_eq!(chunk_for(n, 1), CHUNK, "{n} vertices on one thread");
        for threads in [2, 3, 8, 16, 64] {
            let chunk = chunk_for(n, threads);
            assert!(
                (MIN_CHUNK..=CHUNK).contains(&chunk),
                "{n} on {threads}: {chunk}"
            );
            let chunks = n.div_ceil(chunk);
            // Four a thread where the bounds allow it (rounding up the chunk's size can leave
            // up to three fewer when there are 64 threads).
            if chunk > MIN_CHUNK && chunk < CHUNK {
                assert!(
                    (4 * threads - 3..=4 * threads).contains(&chunks),
                    "{n} on {threads}: {chunks} chunks of {chunk}"
                );
            }
            if chunk == CHUNK {
                assert!(n >= 4 * threads * (CHUNK - 1), "{n} on {threads}: {chunks}");
            }
            if chunk == MIN_CHUNK {
                assert!(n <= 4 * threads * MIN_CHUNK, "{n} on {threads}: {chunks}");
            }
        }
    }
}

/// Against a triangle with a corner resting nearer the vertex than the thickness allows
/// (`NearCorner::Depenetration`), an overlap older than the substep is undone only up to
/// `meet` from the plane, what the pair closed within the substep still up to the whole
/// thickness; `meet` is asked only of a contact that touches.
#[test]
fn an_old_overlap_near_a_corner_is_undone_only_as_far_as_the_edges_allow() {
    let tri = [0u32, 1, 2];
    let read = [
        Vec4::new(0.0, 0.0, 0.0, 1.0),
        Vec4::new(1.0, 0.0, 0.0, 1.0),
        Vec4::new(0.0, 1.0, 0.0, 1.0),
    ];
    let plane = Plane::of(read.map(|x| x.xyz()));
    let params = SelfCollision {
        thickness: 0.1,
        friction: 0.0,
    };
    let correct = |a: Vec4, prev_a: Vec4, meet: &dyn Fn() -> f32| {
        triangle_correction(
            a, prev_a, &plane, tri, &read, &read, SIDE_FRONT, params, meet,
        )
    };
    let a = Vec4::new(0.25, 0.25, 0.02, 1.0);
    // Equal masses: the vertex takes half of each push.
    let pushed = |prev_a: Vec4, meet: f32| {
        let (da, _) = correct(a, prev_a, &|| meet).expect("it touches");
        2.0 * da.z
    };
    let share = DEPENETRATION * params.thickness;
    // 0.02 off the plane since before the substep: a share of the overlap where the whole
    // thickness can be met, up to `meet` where it cannot, nothing past it.
    assert!((pushed(a, 0.1) - share).abs() < 1e-6);
    assert!((pushed(a, 0.05) - 0.03).abs() < 1e-6);
    assert_eq!(pushed(a, 0.01), 0.0);
    // Come from 0.2 off within the substep: out to the thickness whatever `meet` is.
    let from = Vec4::new(0.25, 0.25, 0.2, 1.0);
    assert!((pushed(from, 0.01) - 0.08).abs() < 1e-6);
    // Not touching: `meet` is not asked.
    let far = Vec4::new(0.25, 0.25, 0.5, 1.0);
    assert!(correct(far, far, &|| panic!("asked")).is_none());
}
