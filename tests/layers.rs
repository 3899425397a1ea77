//! The crate's folders import only downward: each module may use the modules of lower layers
//! (and its own), never one of the same or a higher layer. This reads the sources' import
//! paths (`crate::…`, `super::…`), so an arrow running back up fails here, not in a review.
//!
//! The layers, bottom to top, are the ones `src/lib.rs` and `src/solver/mod.rs` document.

use std::path::{Path, PathBuf};

/// Module paths (from the crate root) and their layers; a file belongs to the longest prefix.
const LAYERS: &[(&str, u32)] = &[
    // The solver, bottom to top.
    ("solver::limits", 0),
    ("solver::parallel", 0),
    ("solver::mesh", 1),
    ("solver::constraints", 2),
    ("solver::collision", 2),
    ("solver::metrics", 2),
    ("solver::air", 3),
    ("solver::step", 4),
    ("solver::fuzz", 5),
    ("solver", 5),
    // The Bevy side.
    ("foundation", 10),
    ("collider", 11),
    ("wind", 11),
    ("render", 11),
    ("cloth", 12),
    ("gpu", 13),
    ("editor", 14),
    ("", 15),
];

/// The room (layer entry) a module path belongs to.
fn room(module: &[String]) -> (&'static str, u32) {
    let joined = module.join("::");
    LAYERS
        .iter()
        .filter(|(prefix, _)| {
            prefix.is_empty() || joined == *prefix || joined.starts_with(&format!("{prefix}::"))
        })
        .max_by_key(|(prefix, _)| prefix.len())
        .copied()
        .expect("the crate root matches everything")
}

/// The module path of a source file: `src/solver/step/state.rs` → `solver::step::state`,
/// `src/solver/step/mod.rs` → `solver::step`, `src/lib.rs` → the root.
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).expect("under src");
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_owned())
        .collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts
}

/// The code of a file without comment lines and without its `#[cfg(test)]` modules (tests
/// may exercise anything).
fn code(text: &str) -> String {
    let mut code: String = text
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n");
    while let Some(at) = code.find("#[cfg(test)]\nmod ") {
        let semicolon = code[at..].find(';').map(|k| at + k);
        let open = code[at..].find('{').map(|k| at + k);
        let open = match (open, semicolon) {
            // `mod tests;`: the module is a file of its own (its imports are its own).
            (_, Some(end)) if open.is_none_or(|o| end < o) => {
                code.replace_range(at..=end, "");
                continue;
            }
            (Some(open), _) => open,
            _ => break,
        };
        let mut depth = 0;
        let mut close = code.len();
        for (k, c) in code[open..].char_indices() {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        close = open + k + 1;
                        break;
                    }
                }
                _ => {}
            }
        }
        code.replace_range(at..close, "");
    }
    code
}

/// Every path an import or an expression names through `crate::` or `super::`, resolved to
/// a module path (as far as it goes: `crate::solver::mesh::Grid` → `solver::mesh::Grid`).
fn named_paths(module: &[String], code: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let bytes = code.as_bytes();
    let mut i = 0;
    while i < code.len() {
        let rest = &code[i..];
        let (base, skip) = if rest.starts_with("crate::") && !prev_is_ident(bytes, i) {
            (Vec::new(), "crate::".len())
        } else if rest.starts_with("super::") && !prev_is_ident(bytes, i) {
            // `super` of module `a::b` (file `a/b.rs`) is `a`; of module `a` (file `a/mod.rs`)
            // it is the parent of `a`. Chains climb further.
            let mut base: Vec<String> = module.to_vec();
            let mut skip = 0;
            while code[i + skip..].starts_with("super::") {
                base.pop();
                skip += "super::".len();
            }
            (base, skip)
        } else {
            i += rest.chars().next().map_or(1, char::len_utf8);
            continue;
        };
        i += skip;
        for tail in expand(&code[i..]) {
            let mut p = base.clone();
            p.extend(tail);
            out.push(p);
        }
    }
    out
}

fn prev_is_ident(bytes: &[u8], i: usize) -> bool {
    i > 0 && (bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_' || bytes[i - 1] == b':')
}

/// The module segments a path continues with: `a::b::C` → `[a, b, C]`; a group
/// `{a::X, b}` → each member's segments.
fn expand(s: &str) -> Vec<Vec<String>> {
    if let Some(inner) = s.strip_prefix('{') {
        let mut depth = 0;
        let mut end = inner.len();
        for (k, c) in inner.char_indices() {
            match c {
                '{' => depth += 1,
                '}' if depth == 0 => {
                    end = k;
                    break;
                }
                '}' => depth -= 1,
                _ => {}
            }
        }
        let body = &inner[..end];
        let mut members = Vec::new();
        let (mut depth, mut start) = (0, 0);
        for (k, c) in body.char_indices() {
            match c {
                '{' => depth += 1,
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    members.push(&body[start..k]);
                    start = k + 1;
                }
                _ => {}
            }
        }
        members.push(&body[start..]);
        return members
            .into_iter()
            .map(str::trim)
            .filter(|m| !m.is_empty() && *m != "self")
            .flat_map(expand)
            .collect();
    }
    let mut segs = Vec::new();
    let mut rest = s;
    loop {
        let len = rest
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        if len == 0 {
            break;
        }
        segs.push(rest[..len].to_owned());
        rest = &rest[len..];
        match rest.strip_prefix("::") {
            Some(r) if r.starts_with('{') => {
                let mut out = Vec::new();
                for tail in expand(r) {
                    let mut p = segs.clone();
                    p.extend(tail);
                    out.push(p);
                }
                return out;
            }
            Some(r) => rest = r,
            None => break,
        }
    }
    vec![segs]
}

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("src is readable") {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Every import that runs sideways or up, as `file: path (room layer → room layer)`.
fn violations() -> Vec<String> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    files.sort();
    assert!(files.len() > 40, "found only {} source files", files.len());
    let mut out = Vec::new();
    for file in &files {
        let module = module_of(&src, file);
        let (from, from_layer) = room(&module);
        let text = std::fs::read_to_string(file).expect("a source file");
        for path in named_paths(&module, &code(&text)) {
            let (to, to_layer) = room(&path);
            if to != from && to_layer >= from_layer {
                out.push(format!(
                    "{}: {} ({from} {from_layer} → {to} {to_layer})",
                    file.strip_prefix(&src).unwrap().display(),
                    path.join("::"),
                ));
            }
        }
    }
    out.sort();
    out.dedup();
    out
}

#[test]
fn every_folder_imports_only_downward() {
    let bad = violations();
    assert!(
        bad.is_empty(),
        "imports that run sideways or up ({}):\n{}",
        bad.len(),
        bad.join("\n")
    );
}

#[test]
fn the_solver_imports_nothing_from_bevy() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/solver");
    let mut files = Vec::new();
    sources(&src, &mut files);
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        for (n, line) in code(&text).lines().enumerate() {
            assert!(
                !line.contains("bevy::") && !line.contains("bevy_"),
                "{}:{}: the solver must not use Bevy: {line}",
                file.display(),
                n + 1
            );
        }
    }
}

/// The checker itself: an upward import is found, a grouped one too, and `super` resolves.
#[test]
fn the_checker_finds_what_it_should() {
    let m = |s: &str| s.split("::").map(str::to_owned).collect::<Vec<_>>();
    let paths = named_paths(
        &m("solver::mesh::grid"),
        "use crate::{cloth::Cloth, solver::{step::Simulation, limits}};\nuse super::topology::X;\nlet a = super::super::Grid;",
    );
    let rooms: Vec<&str> = paths.iter().map(|p| room(p).0).collect();
    assert_eq!(
        rooms,
        [
            "cloth",
            "solver::step",
            "solver::limits",
            "solver::mesh",
            "solver"
        ]
    );
    let (_, low) = room(&m("solver::mesh::topology"));
    let (_, high) = room(&m("gpu::plugin"));
    assert!(low < high);
}
