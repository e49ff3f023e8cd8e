//! The crate's top-level modules form no import cycle: no module uses a module that uses it back,
//! directly or through others. Read from the sources (code only: comments and doc links, which
//! import nothing, are skipped); a submodule counts as part of its top-level module.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Top-level module -> the top-level modules its code names as `crate::m`.
fn dependencies() -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    let modules: Vec<String> =
        lib.lines().filter_map(|l| l.trim().strip_prefix("pub mod ")).map(|m| m.trim_end_matches(';').to_string()).collect();
    let mut deps = BTreeMap::new();
    for m in &modules {
        let mut files = vec![src.join(format!("{m}.rs"))];
        if let Ok(dir) = std::fs::read_dir(src.join(m)) {
            files.extend(dir.filter_map(|e| e.ok()).map(|e| e.path()).filter(|p| p.extension().is_some_and(|x| x == "rs")));
        }
        let mut used = BTreeSet::new();
        for f in files.iter().filter(|f| f.exists()) {
            for line in std::fs::read_to_string(f).unwrap().lines() {
                let code = line.split("//").next().unwrap_or("");
                for (i, _) in code.match_indices("crate::") {
                    let rest = &code[i + 7..];
                    // `crate::m::…` or `crate::{a::…, b::…}`.
                    let names: Vec<&str> = match rest.strip_prefix('{') {
                        Some(group) => group.split([',', '}']).map(str::trim).collect(),
                        None => vec![rest],
                    };
                    for n in names {
                        let name: String = n.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                        if modules.contains(&name) && &name != m {
                            used.insert(name);
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
    assert!(deps.len() > 10 && deps["simulation"].contains("has"), "the reader found no dependencies: {deps:?}");
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
