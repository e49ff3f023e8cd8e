//! The crate's modules form no import cycle: no module uses a module that uses it back, directly
//! or through others, and no module outside the inverse layer uses it. Read from the sources
//! (code only: comments and doc links, which import nothing, are skipped); the modules are the
//! root's and the layers' children (`physics::grid`, `inverse::cost`, ...), each with its
//! submodules.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The crate's modules: the root's, and the children of the layers (`physics::grid`, ...).
fn modules(src: &Path) -> Vec<String> {
    let names = |file: &Path| -> Vec<String> {
        std::fs::read_to_string(file)
            .unwrap()
            .lines()
            .filter_map(|l| l.trim().strip_prefix("pub mod "))
            .map(|m| m.trim_end_matches(';').to_string())
            .collect()
    };
    let mut out = Vec::new();
    for m in names(&src.join("lib.rs")) {
        match std::fs::metadata(src.join(&m).join("mod.rs")) {
            Ok(_) if m == "physics" || m == "inverse" => {
                out.extend(names(&src.join(&m).join("mod.rs")).into_iter().map(|c| format!("{m}::{c}")))
            }
            _ => out.push(m),
        }
    }
    out
}

/// The `.rs` files of module `m` (`a::b` lives in `a/b.rs` or `a/b/**.rs`).
fn files(src: &Path, m: &str) -> Vec<std::path::PathBuf> {
    let base = src.join(m.replace("::", "/"));
    let mut out = vec![base.with_extension("rs")];
    let mut dirs = vec![base];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().filter_map(|e| e.ok()) {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.into_iter().filter(|f| f.exists()).collect()
}

/// Module -> the modules its code names as `crate::…` (the longest module path that matches).
fn dependencies() -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let modules = modules(&src);
    let mut deps = BTreeMap::new();
    for m in &modules {
        let mut used = BTreeSet::new();
        for f in files(&src, m) {
            for line in std::fs::read_to_string(f).unwrap().lines() {
                let code = line.split("//").next().unwrap_or("");
                for (i, _) in code.match_indices("crate::") {
                    let rest = &code[i + 7..];
                    // `crate::a::b::…` or `crate::{a::b::…, c::…}`.
                    let paths: Vec<&str> = match rest.strip_prefix('{') {
                        Some(group) => group.split([',', '}']).map(str::trim).collect(),
                        None => vec![rest],
                    };
                    for p in paths {
                        let path: String = p.chars().take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':').collect();
                        if let Some(n) =
                            modules.iter().filter(|n| path == **n || path.starts_with(&format!("{n}::"))).max_by_key(|n| n.len())
                        {
                            if n != m {
                                used.insert(n.clone());
                            }
                        }
                    }
                }
            }
        }
        deps.insert(m.clone(), used);
    }
    deps
}

#[test]
fn no_module_imports_a_module_that_imports_it_back() {
    let deps = dependencies();
    assert!(deps.len() > 15 && deps["simulation"].contains("physics::propagation"), "the reader found no dependencies: {deps:?}");
    // The forward model (physics, simulation, scenario, reference, ...) knows nothing of the
    // inverse layer: no module outside it uses it.
    assert!(deps["inverse::element"].contains("inverse::cost"), "the reader found no dependencies of the inverse layer: {deps:?}");
    for (m, used) in deps.iter().filter(|(m, _)| !m.starts_with("inverse::")) {
        assert!(!used.iter().any(|u| u.starts_with("inverse::")), "{m} uses the inverse layer: {used:?}");
    }
    // Depth-first search for a cycle, reporting its path.
    fn visit<'a>(m: &'a str, deps: &'a BTreeMap<String, BTreeSet<String>>, path: &mut Vec<&'a str>, done: &mut BTreeSet<&'a str>) {
        if let Some(i) = path.iter().position(|p| *p == m) {
            panic!("import cycle: {} -> {m}", path[i..].join(" -> "));
        }
        if done.contains(m) {
            return;
        }
        path.push(m);
        for n in &deps[m] {
            visit(n, deps, path, done);
        }
        path.pop();
        done.insert(m);
    }
    let mut done = BTreeSet::new();
    for m in deps.keys() {
        visit(m, &deps, &mut Vec::new(), &mut done);
    }
}
