//! The documentation's links resolve: every relative link in README.md and
//! docs/*.md names a file that exists and, into a Markdown file, a heading
//! that exists there (GitHub's anchor rule). And the README's minimal scene
//! is `configs/minimal.toml` verbatim (which `validate_accepts_every_shipped_config`
//! validates), so the scene a newcomer copies is one that is checked.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use voxflex_integration_tests::repo_root;

/// The Markdown files whose links are checked.
fn pages(root: &Path) -> Vec<PathBuf> {
    let mut out = vec![root.join("README.md"), root.join("docs/fronts/front.md")];
    for e in std::fs::read_dir(root.join("docs")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            out.push(p);
        }
    }
    out
}

/// The text outside fenced code blocks, line by line.
fn prose(text: &str) -> Vec<&str> {
    let mut inside = false;
    text.lines()
        .filter(|l| {
            if l.starts_with("```") {
                inside = !inside;
                return false;
            }
            !inside
        })
        .collect()
}

/// GitHub's anchor of a heading: lower case, punctuation other than `-`
/// and `_` dropped, spaces as `-`.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | ' '))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// Every anchor of a Markdown file (repeated headings get `-1`, `-2`, …).
fn anchors(text: &str) -> HashSet<String> {
    let mut seen = std::collections::HashMap::<String, usize>::new();
    let mut out = HashSet::new();
    for line in prose(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if (1..=6).contains(&hashes) && line[hashes..].starts_with(' ') {
            let s = slug(&line[hashes + 1..]);
            let n = seen.entry(s.clone()).or_default();
            out.insert(if *n == 0 {
                s.clone()
            } else {
                format!("{s}-{n}")
            });
            *n += 1;
        }
    }
    out
}

/// The targets of the inline links `[text](target)` of a line.
fn link_targets(line: &str) -> Vec<&str> {
    line.match_indices("](")
        .filter_map(|(i, _)| {
            let rest = &line[i + 2..];
            rest.find(')').map(|end| &rest[..end])
        })
        .filter(|t| !t.contains(' '))
        .collect()
}

#[test]
fn every_relative_link_in_the_docs_resolves() {
    let root = repo_root();
    let mut checked = 0;
    let mut broken = vec![];
    for page in pages(&root) {
        let text = std::fs::read_to_string(&page).unwrap();
        for line in prose(&text) {
            for target in link_targets(line) {
                if target.starts_with("http://") || target.starts_with("https://") {
                    continue;
                }
                checked += 1;
                let (path, fragment) = target.split_once('#').unwrap_or((target, ""));
                let file = if path.is_empty() {
                    page.clone()
                } else {
                    page.parent().unwrap().join(path)
                };
                let name = page.strip_prefix(&root).unwrap().display().to_string();
                if !file.exists() {
                    broken.push(format!("{name}: {target} (no such file)"));
                } else if !fragment.is_empty()
                    && file.extension().is_some_and(|x| x == "md")
                    && !anchors(&std::fs::read_to_string(&file).unwrap()).contains(fragment)
                {
                    broken.push(format!("{name}: {target} (no such heading)"));
                }
            }
        }
    }
    assert!(
        checked > 50,
        "only {checked} links found: is the link parser broken?"
    );
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn the_anchor_rule_matches_githubs() {
    assert_eq!(
        slug("Direct volume rendering (`[render]`)"),
        "direct-volume-rendering-render"
    );
    assert_eq!(
        slug("Warnings in `metrics.json`"),
        "warnings-in-metricsjson"
    );
    assert_eq!(slug("ROI maps: Dice vs λ"), "roi-maps-dice-vs-λ");
    assert_eq!(
        slug("FEM cantilever (`fem_cantilever`)"),
        "fem-cantilever-fem_cantilever"
    );
    let a = anchors("# A\n```\n# not a heading\n```\n## A\n");
    assert_eq!(a, HashSet::from(["a".to_string(), "a-1".to_string()]));
}

#[test]
fn the_readme_minimal_scene_is_configs_minimal_toml() {
    let root = repo_root();
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let start = readme
        .find("## A minimal scene")
        .expect("README has a minimal scene section");
    let block = &readme[start..];
    let open = block.find("```toml\n").expect("a toml block") + "```toml\n".len();
    let close = block[open..].find("```").expect("the block ends") + open;
    let config = std::fs::read_to_string(root.join("configs/minimal.toml")).unwrap();
    assert_eq!(
        &block[open..close],
        config,
        "README's minimal scene and configs/minimal.toml differ"
    );
}
