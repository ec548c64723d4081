//! The *Rendering* panel, per-map 3D visibility, Save view as PNG and the
//! saved scene's camera, driven through the viewer's UI headless
//! (egui_kittest) on the built-in head phantom scene on the CPU, with the
//! real `.so` plugins from `target/<profile>/` (build them first).
//!
//! - MIP, a dragged transfer-function point and a map hidden with its
//!   ROI-panel checkbox each change the 3D image's pixels; back to
//!   composite and ticking the map again give the earlier images back
//!   exactly;
//! - Save view as PNG writes the 3D view at the camera's size, not blank;
//!   the scene saved with it holds the camera and transfer function, and
//!   `voxflex run` of it renders the same image (within 2/255 on 99 % of
//!   the pixels).

use egui::{Event, Modifiers, PointerButton, Pos2};
mod common;

use common::{run_saved_scene, wait, wait_for_writes};
use egui_kittest::Harness;
use egui_kittest::kittest::{NodeT as _, Queryable};
use std::path::Path;
use voxflex_runtime::session::GrowthParams;
use voxflex_viewer::app::ViewerApp;
use voxflex_viewer::protocol::Command;
use voxflex_viewer::render_options::TfSource;

fn open_phantom() -> Harness<'static, ViewerApp> {
    let mut h = common::phantom_viewer(&["chainmail", "raycast"], None);
    wait(&mut h, "the first images", |a| {
        a.ready() && a.render_panel().options().is_some()
    });
    h
}

/// The 3D image once every change was applied and a full-quality image
/// newer than image number `after` arrived.
fn image_after(h: &mut Harness<'static, ViewerApp>, after: u64, what: &str) -> Vec<u8> {
    wait(h, what, |a| {
        a.render_panel().settled() && a.render_image().1 > after && a.ready()
    });
    let errors: Vec<_> = h
        .state()
        .messages()
        .iter()
        .filter(|m| m.starts_with("error"))
        .cloned()
        .collect();
    assert!(errors.is_empty(), "{what}: {errors:?}");
    h.state()
        .render_image()
        .0
        .expect("a 3D image")
        .pixels
        .clone()
}

fn renders(h: &Harness<'static, ViewerApp>) -> u64 {
    h.state().render_image().1
}

fn differing(a: &[u8], b: &[u8]) -> usize {
    a.iter().zip(b).filter(|(x, y)| x != y).count()
}

fn drag(h: &mut Harness<'static, ViewerApp>, from: Pos2, to: Pos2) {
    h.hover_at(from);
    h.step();
    h.event(Event::PointerButton {
        pos: from,
        button: PointerButton::Primary,
        pressed: true,
        modifiers: Modifiers::NONE,
    });
    h.step();
    for k in 1..=5 {
        h.hover_at(from + (to - from) * (k as f32 / 5.0));
        h.step();
    }
    h.event(Event::PointerButton {
        pos: to,
        button: PointerButton::Primary,
        pressed: false,
        modifiers: Modifiers::NONE,
    });
    h.step();
}

/// The ROI row's visibility checkbox: the first checkbox of the Maps &
/// model tab (the ROI panel is above the parameter form).
fn roi_checkbox<'a>(h: &'a Harness<'static, ViewerApp>) -> egui_kittest::Node<'a> {
    // The first checkbox that is not the panel's connectivity setting.
    h.get_all_by_role(egui::accesskit::Role::CheckBox)
        .find(|n| {
            !n.accesskit_node()
                .label()
                .is_some_and(|l| l.contains("connectivity"))
        })
        .expect("the map's checkbox")
}

/// A primary click at `pos` (pressed a frame before it is let go).
fn click_at(h: &mut Harness<'static, ViewerApp>, pos: Pos2) {
    h.hover_at(pos);
    h.step();
    for pressed in [true, false] {
        h.event(Event::PointerButton {
            pos,
            button: PointerButton::Primary,
            pressed,
            modifiers: Modifiers::NONE,
        });
        h.step();
    }
}

/// Seeds a map in the brain and grows it to the end.
fn grow_a_map(h: &mut Harness<'static, ViewerApp>) {
    let n = renders(h);
    h.state().send(Command::AddRoi {
        seed: [40.0, 0.0, 15.0],
        params: GrowthParams::default(),
        run_to_end: true,
    });
    wait(h, "the grown map", |a| {
        a.rois().len() == 1 && a.rois()[0].info.converged
    });
    image_after(h, n, "the image with the map");
}

#[test]
fn mip_a_dragged_tf_point_and_a_hidden_map_each_change_the_3d_image() {
    let mut h = open_phantom();
    grow_a_map(&mut h);
    let base = h.state().render_image().0.unwrap().pixels.clone();
    h.get_by_label("Rendering").click();
    h.step();
    // The panel settles its width over a few frames; click after.
    for _ in 0..6 {
        h.step();
    }

    // MIP, then back to composite.
    let n = renders(&h);
    h.get_by_label("MIP").click();
    let mip = image_after(&mut h, n, "the MIP image");
    assert!(differing(&mip, &base) > 1000, "MIP changes the image");
    let n = renders(&h);
    h.get_by_label("Composite").click();
    let back = image_after(&mut h, n, "the composite image again");
    assert_eq!(
        differing(&back, &base),
        0,
        "composite again is the first image"
    );

    // A click in the curve area turns the preset into points; then drag
    // the last but one (the ramp's light, 30 % opaque one) down to
    // transparent.
    let n = renders(&h);
    let p0 = h.state().render_panel().point_pos(0);
    assert!(p0.is_none(), "a preset has no points to drag");
    let (lo, hi) = h.state().render_panel().info_range().unwrap();
    let at = h
        .state()
        .render_panel()
        .editor_pos(lo + 0.05 * (hi - lo), 0.0)
        .expect("the editor is drawn");
    click_at(&mut h, at);
    let points = image_after(&mut h, n, "the image with the editor's points");
    assert!(
        matches!(
            h.state().render_panel().options().unwrap().tf,
            TfSource::Points(_)
        ),
        "a click in the editor starts control points"
    );
    let last = match &h.state().render_panel().options().unwrap().tf {
        TfSource::Points(p) => p.points().len() - 2,
        _ => unreachable!(),
    };
    let from = h.state().render_panel().point_pos(last).expect("drawn");
    let n = renders(&h);
    drag(&mut h, from, from + egui::vec2(0.0, 60.0));
    let dragged = image_after(&mut h, n, "the image after the drag");
    let TfSource::Points(p) = &h.state().render_panel().options().unwrap().tf else {
        unreachable!()
    };
    assert!(
        p.points()[last].opacity < 0.1,
        "the drag lowered the point: {:?}",
        p.points()[last]
    );
    assert!(
        differing(&dragged, &points) > 1000,
        "the dragged point changes the image"
    );

    // Hide the map in 3D with its checkbox in the ROI panel (the first
    // checkbox of the Maps & model tab), then show it again.
    let id = h.state().rois()[0].info.id;
    h.get_by_label("Maps & model").click();
    for _ in 0..6 {
        h.step();
    }
    let n = renders(&h);
    roi_checkbox(&h).click();
    h.step();
    assert!(
        !h.state_mut().roi_panel_mut().style(id).visible,
        "the click unticked the map"
    );
    let hidden = image_after(&mut h, n, "the image without the map");
    assert!(
        differing(&hidden, &dragged) > 1000,
        "hiding the map changes the 3D image"
    );
    let n = renders(&h);
    roi_checkbox(&h).click();
    let shown = image_after(&mut h, n, "the image with the map again");
    assert_eq!(
        differing(&shown, &dragged),
        0,
        "shown again: the same image"
    );
}

fn read_png(path: &Path) -> image::RgbaImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()))
        .to_rgba8()
}

#[test]
fn a_saved_view_and_scene_render_the_same_image_with_voxflex_run() {
    let mut h = open_phantom();
    // Orbit the 3D view (the bottom-right quarter of the views).
    let (top_right, bottom_left) = (
        h.state().slice_rect(1).unwrap(),
        h.state().slice_rect(2).unwrap(),
    );
    let centre = Pos2::new(top_right.center().x, bottom_left.center().y);
    let n = renders(&h);
    drag(&mut h, centre, centre + egui::vec2(60.0, -30.0));
    image_after(&mut h, n, "the orbited view");
    // Custom points, a clip plane and MIP off (composite, shaded).
    let mut o = h.state().render_panel().options().unwrap().clone();
    o.tf = TfSource::Points(voxflex_viewer::tf_points::TfPoints::ramp(-200.0, 1500.0));
    o.clips[0].enabled = true;
    o.clips[0].at_mm = -20.0;
    let n = renders(&h);
    h.state_mut().render_panel_mut().set_options(o);
    let shown = image_after(&mut h, n, "the clipped view");

    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("view.png");
    let scene = dir.path().join("saved.toml");
    h.state().send(Command::SaveViewPng(png.clone()));
    h.state().send(Command::SaveScene(scene.clone()));
    wait_for_writes(&mut h, 2);
    let mine = read_png(&png);
    assert_eq!(
        (mine.width(), mine.height()),
        (384, 384),
        "the camera's size"
    );
    assert_eq!(mine.as_raw(), &shown, "the PNG is the view as shown");
    let colours: std::collections::HashSet<_> = mine.pixels().collect();
    assert!(colours.len() > 200, "not blank: {} colours", colours.len());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        2,
        "no temporary file left"
    );

    let text = std::fs::read_to_string(&scene).unwrap();
    for key in [
        "target_mm",
        "azimuth_deg",
        "points",
        "clip_planes",
        "width = 384",
    ] {
        assert!(text.contains(key), "{key} in the saved scene:\n{text}");
    }
    let out = dir.path().join("out");
    run_saved_scene(&scene, &out, dir.path(), &text);
    let theirs = read_png(&out.join("render.png"));
    assert_eq!(theirs.dimensions(), mine.dimensions());
    let close = mine
        .as_raw()
        .chunks(4)
        .zip(theirs.as_raw().chunks(4))
        .filter(|(a, b)| a.iter().zip(*b).all(|(x, y)| x.abs_diff(*y) <= 2))
        .count();
    let total = (mine.width() * mine.height()) as usize;
    eprintln!("{close} of {total} pixels within 2/255");
    assert!(
        close * 100 >= total * 99,
        "{close} of {total} pixels within 2/255"
    );
}

#[test]
fn save_view_as_png_refuses_a_path_it_cannot_write() {
    let mut h = open_phantom();
    let dir = tempfile::tempdir().unwrap();
    h.state().send(Command::SaveViewPng(
        dir.path().join("no-such-dir/view.png"),
    ));
    h.state()
        .send(Command::SaveViewPng(dir.path().join("view.jpg")));
    wait(&mut h, "two errors", |a| {
        a.messages()
            .iter()
            .filter(|m| m.starts_with("error"))
            .count()
            == 2
    });
    let m = h.state().messages().join("\n");
    assert!(m.contains("no-such-dir") && m.contains(".png"), "{m}");
}
