//! `semloc run --export-map`: the PLY point cloud of the map, on a small synthetic street.

use std::path::Path;

use crate::common::{run_parked, s, text};

/// A parsed PLY vertex: x, y, z (m), class, observations, frames found and visible.
struct Vertex {
    p: [f64; 3],
    class: u8,
    obs: u8,
    found: u32,
    visible: u32,
}

/// Parses the PLY semloc writes, checking its header against its body.
fn read_ply(path: &Path) -> Vec<Vertex> {
    let text = std::fs::read_to_string(path).unwrap();
    let (header, body) = text.split_once("end_header\n").expect("a PLY header");
    assert!(header.starts_with("ply\nformat ascii 1.0\n"), "{header}");
    let n: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .expect("element vertex")
        .parse()
        .unwrap();
    let props: Vec<&str> = header.lines().filter_map(|l| l.strip_prefix("property ")).collect();
    assert_eq!(props.len(), 12, "{props:?}");
    let lines: Vec<&str> = body.lines().collect();
    assert_eq!(lines.len(), n, "vertex count in the header");
    lines
        .iter()
        .map(|l| {
            let f: Vec<&str> = l.split(' ').collect();
            assert_eq!(f.len(), props.len(), "{l}");
            let v = |i: usize| f[i].parse::<f64>().unwrap();
            Vertex {
                p: [v(0), v(1), v(2)],
                class: f[6].parse().unwrap(),
                obs: f[7].parse().unwrap(),
                found: f[10].parse().unwrap(),
                visible: f[11].parse().unwrap(),
            }
        })
        .collect()
}

fn run(semantics: &str, out: &Path, map: &Path) {
    let o = run_parked(out, &["--semantics", semantics, "--export-map", s(map)]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("confirmed points"), "{}", text(&o));
}

#[test]
fn run_writes_the_map_with_classes() {
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("map.ply");
    run("motion", &dir.path().join("out"), &map);
    let pts = read_ply(&map);
    assert!(pts.len() > 200, "{} points", pts.len());
    assert!(pts.iter().all(|v| v.obs >= 2 && v.p.iter().all(|c| c.is_finite())));
    // The world is the first left camera: the street is in front of it and the road 1.65 m
    // below it (y down), nothing far below the road.
    let mut z: Vec<f64> = pts.iter().map(|v| v.p[2]).collect();
    z.sort_by(f64::total_cmp);
    assert!(z[z.len() / 2] > 3.0, "median depth {}", z[z.len() / 2]);
    assert!(pts.iter().filter(|v| v.p[1] > 2.5).count() * 50 < pts.len(), "points below the road");
    // Labels came from the dataset: classes on almost every point, several classes.
    let labelled = pts.iter().filter(|v| v.class != 255).count();
    assert!(labelled * 10 >= pts.len() * 9, "{labelled} of {} labelled", pts.len());
    assert!(pts.iter().all(|v| v.class == 255 || v.class < 11));
    let mut classes: Vec<u8> = pts.iter().map(|v| v.class).filter(|&c| c != 255).collect();
    classes.sort_unstable();
    classes.dedup();
    assert!(classes.len() >= 3, "classes {classes:?}");
    // The road (3) is there.
    assert!(classes.contains(&3), "classes {classes:?}");
    // Tracking counts over the 10 frames: every confirmed point was matched at least once (the
    // keyframe that made it), most of them again, some in nearly every frame; a point is rarely
    // found more often than predicted in view (only a fused point, which adds its duplicate's
    // counts).
    assert!(pts.iter().all(|v| v.found >= 1 && v.visible >= 1));
    let mut found: Vec<u32> = pts.iter().map(|v| v.found).collect();
    found.sort_unstable();
    assert!(found[found.len() / 2] >= 2, "median found {}", found[found.len() / 2]);
    assert!(found[found.len() - 1] >= 8, "most found {}", found[found.len() - 1]);
    let over = pts.iter().filter(|v| v.found > v.visible).count();
    assert!(over * 50 <= pts.len(), "{over} of {} found more than visible", pts.len());
}

#[test]
fn without_labels_points_have_no_class() {
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("map.ply");
    run("off", &dir.path().join("out"), &map);
    let pts = read_ply(&map);
    assert!(pts.len() > 200, "{} points", pts.len());
    assert!(pts.iter().all(|v| v.class == 255));
}

#[test]
fn a_missing_folder_is_refused_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = run_parked(&out, &["--export-map", s(&dir.path().join("nowhere/map.ply"))]);
    assert!(!o.status.success());
    assert!(text(&o).contains("nowhere") && text(&o).contains("does not exist"), "{}", text(&o));
    assert!(!out.exists(), "nothing is written when the map cannot be");
}
