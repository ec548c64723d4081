//! The viewer driven through its UI, headless (egui_kittest): the
//! built-in head phantom scene (4 mm voxels, ChainMail) on the CPU, the
//! session on its worker thread with the real `.so` plugins from
//! `target/<profile>/` (build them first: `cargo build`).
//!
//! - a click on the axial slice in the brain seeds an ROI map; Run to end
//!   grows it; the map is non-empty and the 3D image changes;
//! - a grab-drag on a slice moves the resampled volume (the voxel value at
//!   a point next to the ventricle changes);
//! - choosing another model in the combo box keeps the ROI maps;
//! - a cut line drawn across the head, then a grab on one side, opens a
//!   gap at the cut (air where the uncut tissue stays tissue); seen from
//!   the front along the cut plane, the 3D view cropped to a slab around
//!   the pull, the gap turns tissue pixels to background, and the axial
//!   slice shows air along the cut line;
//! - unticking the crop box, or the only clip plane, in the *Rendering*
//!   panel gives the uncropped 3D image back;
//! - a carve click turns the voxel under the brush centre to air;
//! - the parameter form files a bad TOML text and the plugin's refusal
//!   under their key, and Apply rebuilds the model;
//! - a scene saved after a grab, run by `voxflex run`, gives the viewer's
//!   volume;
//! - a NIfTI dropped on the window opens in place of the session, a bad
//!   one is refused naming the file; Open recent lists the files newest
//!   first, across runs, and opens them;
//! - the *auto λ* box grows a map at the λ the plateau rule chose and
//!   shows it; bounds applied in the panel hold a map in;
//! - a grab-drag on the 3D view picks the face and moves the volume.

use egui::{Event, Modifiers, PointerButton, Pos2};
mod common;

use common::{run_saved_scene, wait, wait_for_writes};
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use std::path::PathBuf;
use std::time::Duration;
use voxflex_core::camera::Camera;
use voxflex_core::glam::DVec3;
use voxflex_runtime::session::{Seed, SliceImage};
use voxflex_runtime::visualise::RgbaImage;
use voxflex_viewer::app::ViewerApp;
use voxflex_viewer::protocol::Command;
use voxflex_viewer::protocol::SliceFrame;

fn open_phantom() -> Harness<'static, ViewerApp> {
    // File → Open recent in no file: the tests never touch the user's list.
    open_phantom_recent(None)
}

/// The built-in phantom with File → Open recent kept in `store`.
fn open_phantom_recent(store: Option<PathBuf>) -> Harness<'static, ViewerApp> {
    let mut h = common::phantom_viewer(&["chainmail"], store);
    wait(&mut h, "the first images", |a| a.ready());
    h
}

/// The screen point of world point `p` (mm) on slice view `n`.
fn screen_of(h: &Harness<'static, ViewerApp>, n: usize, p: DVec3) -> Pos2 {
    let app = h.state();
    let frame: &SliceFrame = &app.slices().expect("slices")[n];
    let rect = app.slice_rect(n).expect("slice view drawn");
    let [c, r] = frame.slice.world_to_point(p);
    let img = &frame.slice.image;
    Pos2::new(
        rect.min.x + ((c + 0.5) / img.width as f64) as f32 * rect.width(),
        rect.min.y + ((r + 0.5) / img.height as f64) as f32 * rect.height(),
    )
}

fn press(h: &Harness<'static, ViewerApp>, pos: Pos2, pressed: bool, modifiers: Modifiers) {
    h.event(Event::PointerButton {
        pos,
        button: PointerButton::Primary,
        pressed,
        modifiers,
    });
}

/// A primary click at `pos` with `modifiers` held down (pressed a frame
/// before and let go a frame after, as a hand does).
fn click(h: &mut Harness<'static, ViewerApp>, pos: Pos2, modifiers: Modifiers) {
    h.event(Event::ModifiersChanged(modifiers));
    h.hover_at(pos);
    h.step();
    press(h, pos, true, modifiers);
    h.step();
    press(h, pos, false, modifiers);
    h.step();
    h.event(Event::ModifiersChanged(Modifiers::NONE));
    h.step();
}

/// Sets the cursor to world point `p` by clicks on the coronal view (x, z)
/// and then the axial view (x, y), and waits for its value.
fn put_cursor(h: &mut Harness<'static, ViewerApp>, p: DVec3) -> f32 {
    let pos = screen_of(h, 1, p);
    click(h, pos, Modifiers::NONE);
    wait(h, "the axial slice through the click", |a| {
        (a.cursor().z - p.z).abs() < 4.0
            && a.slices()
                .is_some_and(|s| s[0].slice.world_to_pixel(a.cursor()).is_some())
    });
    let pos = screen_of(h, 0, p);
    click(h, pos, Modifiers::NONE);
    wait(h, "the cursor's slices", |a| {
        (a.cursor() - p).length() < 4.0
            && a.slices().is_some_and(|s| {
                s[0].slice.world_to_pixel(a.cursor()).is_some()
                    && s[1].slice.world_to_pixel(a.cursor()).is_some()
            })
    });
    h.state().cursor_value()
}

/// A brain point away from the ventricles (x = 40 mm).
const BRAIN: DVec3 = DVec3::new(40.0, 0.0, 15.0);

fn seed_and_grow(h: &mut Harness<'static, ViewerApp>) {
    put_cursor(h, BRAIN);
    let pos = screen_of(h, 0, BRAIN);
    click(h, pos, Modifiers::COMMAND);
    wait(h, "the new map", |a| a.rois().len() == 1);
    let Seed::World(seed) = h.state().rois()[0].info.seed else {
        panic!("a click seeds at a world point")
    };
    assert!(
        (seed - BRAIN).length() < 4.0,
        "seeded at {seed}, clicked {BRAIN}"
    );
    h.get_by_label("Run to end").click();
    wait(h, "the map to converge", |a| {
        a.rois()[0].info.converged && a.rois()[0].last.is_some()
    });
}

#[test]
fn a_click_on_the_brain_grows_a_map_that_shows_in_3d() {
    let mut h = open_phantom();
    let before = h.state().render_image().0.expect("a 3D image").clone();
    seed_and_grow(&mut h);
    let info = h.state().rois()[0].info.clone();
    // The brain of the 4 mm phantom: a few thousand voxels, not the head.
    assert!(info.voxels_above_half > 1000, "{info:?}");
    assert!(info.voxels_above_half < 50 * 60 * 55 / 2, "{info:?}");
    let (report, _) = h.state().rois()[0].last.expect("growth report");
    assert!(report.steps > 1 && report.useful_fraction() > 0.0);
    wait(&mut h, "a 3D image with the map", |a| {
        a.render_image()
            .0
            .is_some_and(|i| i.pixels != before.pixels)
    });
}

#[test]
fn a_grab_drag_on_a_slice_moves_the_volume() {
    let mut h = open_phantom();
    // Next to the right ventricle (centre x = 10, semi-axis 5 mm), in brain.
    let probe = DVec3::new(22.0, -5.0, 15.0);
    let value = put_cursor(&mut h, probe);
    assert!(
        (value - 30.0).abs() < 1.0,
        "brain (30) at the probe, got {value}"
    );
    h.get_by_label("Grab").click();
    h.step();
    let from = screen_of(&h, 0, DVec3::new(10.0, -5.0, 15.0));
    let to = screen_of(&h, 0, probe + DVec3::new(4.0, 0.0, 0.0));
    h.hover_at(from);
    h.step();
    press(&h, from, true, Modifiers::NONE);
    h.step();
    for s in 1..=10 {
        let p = from + (to - from) * (s as f32 / 10.0);
        h.hover_at(p);
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    press(&h, to, false, Modifiers::NONE);
    h.step();
    wait(&mut h, "the deformed volume at the probe", |a| {
        a.steps() > 0 && (a.cursor_value() - value).abs() > 5.0
    });
}

#[test]
fn a_model_swap_keeps_the_roi_maps() {
    let mut h = open_phantom();
    seed_and_grow(&mut h);
    let before = h.state().rois()[0].info.clone();
    assert_eq!(h.state().model(), Some("chainmail"));
    h.get_by_role_and_label(egui::accesskit::Role::ComboBox, "Model")
        .click();
    h.run_steps(3);
    let models = &h.state().opened().expect("opened").models;
    assert!(models.iter().any(|(m, _)| m == "affine"), "{models:?}");
    h.get_by_label("affine").click();
    wait(&mut h, "the swap", |a| {
        a.model() == Some("affine") && a.steps() > 0
    });
    let after = &h.state().rois()[0].info;
    assert_eq!(
        (after.id, after.seed, after.params),
        (before.id, before.seed, before.params)
    );
    // Re-grown on the bent volume, to convergence again.
    assert!(
        after.converged && after.voxels_above_half > 1000,
        "{after:?}"
    );
}

#[test]
fn the_sliders_regrow_the_selected_map_and_save_writes_it() {
    let mut h = open_phantom();
    seed_and_grow(&mut h);
    let before = h.state().rois()[0].info.clone();
    h.get_by_label("map 0").click();
    h.step();
    h.get_by_role_and_label(egui::accesskit::Role::SpinButton, "λ")
        .set_value_accesskit(3.0);
    wait(&mut h, "the map grown with λ = 3", |a| {
        a.rois()[0].info.params.lambda == 3.0 && a.rois()[0].info.converged
    });
    let after = h.state().rois()[0].info.clone();
    assert_eq!(after.id, before.id);
    assert!(
        after.voxels_above_half < before.voxels_above_half,
        "a smaller λ stops the growth sooner: {} → {}",
        before.voxels_above_half,
        after.voxels_above_half
    );
    let dir = tempfile::tempdir().unwrap();
    h.state_mut().roi_panel_mut().save_dir = dir.path().display().to_string();
    h.get_by_label("Save").click();
    let path = dir.path().join("roi-0.nii.gz");
    wait(&mut h, "the saved map", |a| {
        a.messages().iter().any(|m| m.starts_with("wrote"))
    });
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(&bytes[..2], &[0x1f, 0x8b], "gzip-compressed NIfTI");
}

/// A primary drag on axial view from world point `from` to `to` (mm), in
/// ten moves.
fn drag_axial(h: &mut Harness<'static, ViewerApp>, from: DVec3, to: DVec3) {
    let (a, b) = (screen_of(h, 0, from), screen_of(h, 0, to));
    h.hover_at(a);
    h.step();
    press(h, a, true, Modifiers::NONE);
    h.step();
    for s in 1..=10 {
        h.hover_at(a + (b - a) * (s as f32 / 10.0));
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    press(h, b, false, Modifiers::NONE);
    h.step();
}

/// Grab mode, a drag on the axial view from `from` to `to` (mm), and a
/// wait for the model to step. A busy worker coalesces a drag's targets
/// (the last one counts), so the drag may take fewer steps than moves: at
/// least one; anything queued next (a Release) comes after them all.
fn grab_drag_axial(h: &mut Harness<'static, ViewerApp>, from: DVec3, to: DVec3) {
    h.get_by_label("Grab").click();
    h.step();
    let steps = h.state().steps();
    drag_axial(h, from, to);
    wait(h, "the steps of the grab", |a| a.steps() > steps);
}

/// The probe's value after pulling the left half of the brain 20 mm to
/// the left (−x), with or without a cut first along x = 0 across the
/// whole axial slice.
fn pull_left_half(cut_first: bool) -> f32 {
    let mut h = open_phantom();
    pull_left_half_of(&mut h, cut_first);
    h.state().cursor_value()
}

/// Just right of the cut line of [`pull_left_half_of`], in brain, away
/// from the ventricles.
const PULL_PROBE: DVec3 = DVec3::new(-2.0, 40.0, 15.0);

/// [`pull_left_half`] in `h`: the cursor at [`PULL_PROBE`], the cut along
/// x = 0 (when `cut_first`), the pull and five settling steps.
fn pull_left_half_of(h: &mut Harness<'static, ViewerApp>, cut_first: bool) {
    let probe = PULL_PROBE;
    let value = put_cursor(h, probe);
    assert!((value - 30.0).abs() < 1.0, "brain at the probe: {value}");
    if cut_first {
        h.get_by_label("Cut").click();
        h.step();
        let steps = h.state().steps();
        drag_axial(
            h,
            DVec3::new(0.0, -118.0, 15.0),
            DVec3::new(0.0, 118.0, 15.0),
        );
        wait(h, "the step after the cut", |a| a.steps() > steps);
        assert!(
            h.state().messages().iter().all(|m| !m.starts_with("error")),
            "{:?}",
            h.state().messages()
        );
    }
    grab_drag_axial(
        h,
        DVec3::new(-30.0, 40.0, 15.0),
        DVec3::new(-50.0, 40.0, 15.0),
    );
    // Let the model settle a few frames.
    for _ in 0..5 {
        let steps = h.state().steps();
        h.get_by_label("Step").click();
        wait(h, "a step", |a| a.steps() > steps);
    }
}

#[test]
fn a_cut_then_a_grab_opens_a_gap_across_the_cut_line() {
    let joined = pull_left_half(false);
    let cut = pull_left_half(true);
    eprintln!("probe value after the pull: uncut {joined}, cut {cut}");
    // Uncut, the tissue at the probe stretches and stays tissue; cut, the
    // left half pulls away and the probe lies in the gap (air, −1000).
    assert!(joined > -500.0, "uncut: tissue at the probe, got {joined}");
    assert!(cut < -500.0, "cut: the gap at the probe, got {cut}");
}

/// Pixels a side of the 3D image in the gap test: small (fast), the gap
/// still a few pixels wide.
const GAP_RENDER_PX: u32 = 192;

/// Waits for a full-quality 3D image `px` pixels a side, with every
/// rendering option set so far applied, and returns it.
fn image_at_size(h: &mut Harness<'static, ViewerApp>, px: u32) -> RgbaImage {
    h.state_mut().set_render_size(px);
    wait(h, &format!("a 3D image {px} px a side"), |a| {
        a.render_panel().settled() && a.ready() && a.render_image().0.is_some_and(|i| i.width == px)
    });
    h.state().render_image().0.expect("a 3D image").clone()
}

/// The renderer's background (black) or nearly so.
fn is_background(rgba: &[u8]) -> bool {
    rgba[0].max(rgba[1]).max(rgba[2]) < 8
}

/// Which pixels of `camera`'s image see within `half` mm of the cut plane
/// x = 0, where their rays cross the pull's plane (y of [`PULL_PROBE`]).
fn cut_band(camera: &Camera, half: f64) -> Vec<bool> {
    let mut band = Vec::with_capacity((camera.width * camera.height) as usize);
    for py in 0..camera.height {
        for px in 0..camera.width {
            let r = camera.ray(px as f64, py as f64);
            let p = r.origin + r.dir * ((PULL_PROBE.y - r.origin.y) / r.dir.y);
            band.push(p.x.abs() <= half);
        }
    }
    band
}

/// Rows of the axial slice `s` with an air pixel (black in the
/// soft-tissue window) within 30 mm of the cut line x = 0 and 70 mm of
/// y = 0: all brain in the phantom at the probe's height.
fn rows_with_air_at_the_cut(s: &SliceImage) -> usize {
    (0..s.image.height)
        .filter(|&row| {
            (0..s.image.width).any(|col| {
                let p = s.pixel_to_world(col, row).expect("in the image");
                p.x.abs() <= 30.0
                    && p.y.abs() <= 70.0
                    && s.image.pixels[row * s.image.width + col] == 0
            })
        })
        .count()
}

#[test]
fn a_cut_shows_a_gap_in_the_rendered_image_and_on_the_slice() {
    let mut h = open_phantom();
    wait(&mut h, "the rendering options", |a| {
        a.render_panel().options().is_some()
    });
    // The front camera looks along +y, in the cut plane x = 0: the gap is
    // seen edge-on, through. The 3D view is cropped to a slab 20 mm thick
    // across y around the pull's plane: outside it the gap stays shut, and
    // the face, brain and skull there would hide it.
    let camera = Camera {
        width: GAP_RENDER_PX,
        height: GAP_RENDER_PX,
        ..h.state().opened().expect("opened").camera
    };
    assert!(camera.basis().2.dot(DVec3::Y) > 0.999, "{camera:?}");
    let (lo, hi) = h.state().opened().expect("opened").grid.world_bounds();
    let mut o = h.state().render_panel().options().expect("options").clone();
    o.crop.enabled = true;
    o.crop.min = [lo.x, PULL_PROBE.y - 10.0, lo.z];
    o.crop.max = [hi.x, PULL_PROBE.y + 10.0, hi.z];
    h.state_mut().render_panel_mut().set_options(o);
    put_cursor(&mut h, PULL_PROBE);
    let slice_before = h.state().slices().expect("slices")[0].slice.clone();
    let before = image_at_size(&mut h, GAP_RENDER_PX);
    // Watched at half size: the first image back at full size is rendered
    // after the pull's last step (the worker takes commands in order).
    h.state_mut().set_render_size(GAP_RENDER_PX / 2);
    pull_left_half_of(&mut h, true);
    let after = image_at_size(&mut h, GAP_RENDER_PX);
    let slice_after = h.state().slices().expect("slices")[0].slice.clone();
    assert_eq!(slice_after.index, slice_before.index, "the same slice");

    let band = cut_band(&camera, 30.0);
    let (mut tissue, mut opened, mut background) = (0, 0, [0, 0]);
    for ((b, a), &inside) in before
        .pixels
        .chunks_exact(4)
        .zip(after.pixels.chunks_exact(4))
        .zip(&band)
    {
        if inside {
            background[0] += usize::from(is_background(b));
            background[1] += usize::from(is_background(a));
            tissue += usize::from(!is_background(b));
            opened += usize::from(!is_background(b) && is_background(a));
        }
    }
    let rows = [&slice_before, &slice_after].map(rows_with_air_at_the_cut);
    eprintln!(
        "cut band ({} px): background {} before, {} after; {opened} of its {tissue} \
         tissue px now background; axial slice rows with air at the cut: {} before, {} after",
        band.iter().filter(|&&b| b).count(),
        background[0],
        background[1],
        rows[0],
        rows[1]
    );
    assert!(
        tissue > 1000,
        "the slab's brain fills the band: {tissue} px"
    );
    // Uncut, the pull stretches the tissue: no pixel of it turns to
    // background.
    assert!(
        opened >= 100,
        "the gap shows as background in the 3D image: {opened} px"
    );
    assert_eq!(rows[0], 0, "brain all along the cut line before the cut");
    assert!(
        rows[1] >= 20,
        "air along the cut line on the axial slice: {} rows",
        rows[1]
    );
}

/// Pixels a side of the 3D image in the crop-off test.
const CROP_RENDER_PX: u32 = 128;

/// How many pixels of `image` show the head (not the background).
fn tissue_pixels(image: &RgbaImage) -> usize {
    image
        .pixels
        .chunks_exact(4)
        .filter(|p| !is_background(p))
        .count()
}

/// How many pixels of `a` and `b` differ, and by how much at most (of
/// 255, any channel).
fn pixel_difference(a: &RgbaImage, b: &RgbaImage) -> (usize, u8) {
    a.pixels
        .chunks_exact(4)
        .zip(b.pixels.chunks_exact(4))
        .map(|(p, q)| {
            p.iter()
                .zip(q)
                .map(|(x, y)| x.abs_diff(*y))
                .max()
                .unwrap_or(0)
        })
        .filter(|&d| d > 0)
        .fold((0, 0), |(n, most), d| (n + 1, most.max(d)))
}

/// Clicks the *Rendering* panel's checkbox `label` and checks that the
/// panel took it (a reconfigure is then on its way).
fn tick(h: &mut Harness<'static, ViewerApp>, label: &str, enabled: impl Fn(&ViewerApp) -> bool) {
    let before = enabled(h.state());
    h.get_by_label(label).click();
    h.step();
    assert_ne!(enabled(h.state()), before, "{label} toggled");
}

#[test]
fn unticking_the_crop_box_or_the_clip_plane_gives_the_whole_image_back() {
    let mut h = open_phantom();
    wait(&mut h, "the rendering options", |a| {
        a.render_panel().options().is_some()
    });
    h.get_by_label("Rendering").click();
    // The panel settles its width over a few frames; click after.
    for _ in 0..6 {
        h.step();
    }
    let whole = image_at_size(&mut h, CROP_RENDER_PX);

    // Crop to the half x ≥ 0 (the front camera sees x across the image),
    // then untick *Crop box*.
    let (lo, hi) = h.state().opened().expect("opened").grid.world_bounds();
    let mut o = h.state().render_panel().options().expect("options").clone();
    o.crop.enabled = true;
    o.crop.min = [0.0, lo.y, lo.z];
    o.crop.max = hi.to_array();
    h.state_mut().render_panel_mut().set_options(o);
    let cropped = image_at_size(&mut h, CROP_RENDER_PX);
    let crop_on = |a: &ViewerApp| a.render_panel().options().expect("options").crop.enabled;
    tick(&mut h, "Crop box", crop_on);
    let uncropped = image_at_size(&mut h, CROP_RENDER_PX);

    // The same with the clip plane across z (at the volume's centre,
    // keeping +z), ticked and unticked in the panel.
    let clip_on = |a: &ViewerApp| a.render_panel().options().expect("options").clips[2].enabled;
    tick(&mut h, "clip z", clip_on);
    let clipped = image_at_size(&mut h, CROP_RENDER_PX);
    tick(&mut h, "clip z", clip_on);
    let unclipped = image_at_size(&mut h, CROP_RENDER_PX);

    let count = [&whole, &cropped, &uncropped, &clipped, &unclipped].map(tissue_pixels);
    let (crop_diff, clip_diff) = (
        pixel_difference(&uncropped, &whole),
        pixel_difference(&unclipped, &whole),
    );
    eprintln!(
        "head pixels of {px}²: {} whole, {} cropped, {} unticked ({} px differ from whole, \
         by ≤ {}/255); {} clipped, {} unticked ({} px differ, by ≤ {}/255)",
        count[0],
        count[1],
        count[2],
        crop_diff.0,
        crop_diff.1,
        count[3],
        count[4],
        clip_diff.0,
        clip_diff.1,
        px = CROP_RENDER_PX,
    );
    assert!(count[0] > 2000, "the head fills the view: {}", count[0]);
    // The crop and the clip each take a clear part of the head away…
    for (what, n) in [("cropped", count[1]), ("clipped", count[3])] {
        assert!(
            n * 10 < count[0] * 8,
            "{what}: {n} head px, whole {}",
            count[0]
        );
    }
    // …and unticked, the whole head is back (the same renderer settings
    // as at first: the same image, within a pixel count's rounding).
    let tolerance = count[0] / 200;
    for (what, n) in [("crop box", count[2]), ("clip plane", count[4])] {
        assert!(
            n.abs_diff(count[0]) <= tolerance,
            "{what} unticked: {n} head px, whole {} (cropped {}, clipped {})",
            count[0],
            count[1],
            count[3]
        );
    }
}

#[test]
fn a_carve_click_removes_the_tissue_under_the_brush() {
    let mut h = open_phantom();
    let grid = h.state().opened().expect("opened").grid;
    let air = put_cursor(&mut h, grid.index_to_world(DVec3::ZERO));
    let value = put_cursor(&mut h, BRAIN);
    assert!((value - 30.0).abs() < 1.0, "brain at {BRAIN}: {value}");
    h.get_by_label("Carve").click();
    h.step();
    let pos = screen_of(&h, 0, BRAIN);
    click(&mut h, pos, Modifiers::NONE);
    wait(&mut h, "the carved volume at the brush centre", |a| {
        (a.cursor_value() - air).abs() < 1.0
    });
}

fn read(path: &std::path::Path) -> voxflex_core::volume::Volume {
    voxflex_io::read_volume(path, &voxflex_io::ReadOptions::default())
        .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()))
}

#[test]
fn a_saved_scene_run_by_the_cli_reproduces_the_viewers_volume() {
    let mut h = open_phantom();
    put_cursor(&mut h, DVec3::new(-2.0, 40.0, 15.0));
    grab_drag_axial(
        &mut h,
        DVec3::new(-30.0, 40.0, 15.0),
        DVec3::new(-45.0, 30.0, 15.0),
    );
    h.get_by_label("Release").click();
    let steps = h.state().steps();
    wait(&mut h, "the step after the release", |a| a.steps() > steps);
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("saved.toml");
    let mine = dir.path().join("viewer.nii.gz");
    h.state().send(Command::SaveScene(scene.clone()));
    h.state().send(Command::SaveVolume(mine.clone()));
    wait_for_writes(&mut h, 2);
    let text = std::fs::read_to_string(&scene).unwrap();
    assert!(text.contains("kind = \"grab\""), "{text}");
    let out = dir.path().join("out");
    run_saved_scene(&scene, &out, dir.path(), &text);
    let (a, b) = (read(&mine), read(&out.join("deformed.nii.gz")));
    assert_eq!(a.grid.dims, b.grid.dims);
    let source = voxflex_runtime::session::Session::open(
        &voxflex_runtime::scene::Scene::parse(&text, &scene).unwrap(),
    )
    .unwrap()
    .volume()
    .unwrap()
    .clone();
    let (mut worst, mut moved) = (0.0f32, 0);
    let [nx, ny, nz] = a.grid.dims;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let x = a.get_f32(i, j, k);
                worst = worst.max((x - b.get_f32(i, j, k)).abs());
                moved += usize::from(x != source.get_f32(i, j, k));
            }
        }
    }
    eprintln!("{moved} voxels moved; largest viewer/run difference {worst}");
    assert!(moved > 100, "the grab moved the volume ({moved} voxels)");
    assert!(worst <= 1.0, "largest voxel difference {worst} (units)");
}

/// The form's field for `key` of the model in use.
fn form_field(h: &Harness<'static, ViewerApp>, key: &str) -> voxflex_viewer::param_form::Field {
    let form = h.state().model_panel().form.as_ref().expect("a form");
    form.fields
        .iter()
        .find(|f| f.spec.name == key)
        .unwrap_or_else(|| panic!("no field {key}"))
        .clone()
}

#[test]
fn the_parameter_form_shows_problems_under_their_key_and_applies() {
    use voxflex_viewer::param_form::FieldValue;
    let mut h = open_phantom();
    assert_eq!(
        form_field(&h, "propagation_iterations").value,
        FieldValue::Integer(10),
        "the scene's value"
    );
    // Text that is not TOML: filed under the key as the user types.
    h.get_by_role_and_label(egui::accesskit::Role::MultilineTextInput, "materials *")
        .focus();
    h.step();
    h.event(Event::Text("}".into()));
    h.run_steps(2);
    let m = form_field(&h, "materials");
    assert!(!m.issues.is_empty(), "{m:?}");
    // A table the schema accepts but the plugin refuses: the session's
    // error is filed under the key it names.
    let bad = "[{ range = [-50, 300], constraint = 9.0 }]";
    let panel = h.state_mut().model_panel_mut();
    let form = panel.form.as_mut().unwrap();
    let i = form
        .fields
        .iter()
        .position(|f| f.spec.name == "materials")
        .unwrap();
    form.fields[i].value = FieldValue::Toml(bad.into());
    form.check();
    h.step();
    h.get_by_label("Apply").click();
    wait(&mut h, "the plugin's refusal under `materials`", |a| {
        let f = a.model_panel().form.as_ref().unwrap();
        f.fields
            .iter()
            .any(|f| f.spec.name == "materials" && !f.issues.is_empty())
    });
    // A good table: Apply rebuilds the model, which steps.
    let good = "[{ range = [-50, 300], constraint = 0.5 }]";
    let form = h.state_mut().model_panel_mut().form.as_mut().unwrap();
    form.fields[i].value = FieldValue::Toml(good.into());
    assert!(form.check(), "{:?}", form.fields[i].issues);
    let (steps, errors) = (h.state().steps(), h.state().messages().len());
    h.step();
    h.get_by_label("Apply").click();
    wait(&mut h, "the model rebuilt", |a| a.steps() > steps);
    assert_eq!(
        h.state().messages().len(),
        errors,
        "{:?}",
        h.state().messages()
    );
    assert!(h.state().model_panel().params.contains("constraint = 0.5"));
}

/// Writes phantom `name` at `dims` as a NIfTI file in `dir`.
fn phantom_file(dir: &std::path::Path, name: &str, dims: [usize; 3]) -> PathBuf {
    let path = dir.join(format!("{name}.nii.gz"));
    let v = voxflex_phantom::phantom(name, dims).unwrap();
    voxflex_io::write_volume(&path, v.view()).unwrap();
    path
}

/// A file dropped on the window, as the windowing layer hands it over.
#[derive(Debug)]
struct Dropped(PathBuf);

impl egui::DroppedFile for Dropped {
    fn path(&self) -> &std::path::Path {
        &self.0
    }

    fn bytes(&self) -> Result<Vec<u8>, String> {
        std::fs::read(&self.0).map_err(|e| e.to_string())
    }
}

fn drop_file(h: &mut Harness<'static, ViewerApp>, path: &std::path::Path) {
    h.input_mut()
        .dropped_files
        .push(std::sync::Arc::new(Dropped(path.to_path_buf())));
    h.step();
}

/// Waits until `path` is the session open, with its first images.
fn wait_opened(h: &mut Harness<'static, ViewerApp>, path: &std::path::Path, dims: [usize; 3]) {
    let title = path.display().to_string();
    wait(h, &format!("{title} open"), |a| {
        a.opened()
            .is_some_and(|o| o.title == title && o.grid.dims == dims)
            && a.ready()
    });
}

#[test]
fn a_dropped_file_opens_in_place_and_open_recent_keeps_it_newest_first() {
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("config/voxflex/viewer-recent.txt");
    let cube = phantom_file(dir.path(), "cube", [24, 24, 24]);
    let rings = phantom_file(dir.path(), "rings", [20, 22, 18]);
    let mut h = open_phantom_recent(Some(store.clone()));
    drop_file(&mut h, &cube);
    wait_opened(&mut h, &cube, [24, 24, 24]);
    assert!(h.state().rois().is_empty() && h.state().model().is_none());
    drop_file(&mut h, &rings);
    wait_opened(&mut h, &rings, [20, 22, 18]);
    // A file that is not a volume: refused, naming it; the session stays.
    let bad = dir.path().join("bad.nii");
    std::fs::write(&bad, "not a volume").unwrap();
    drop_file(&mut h, &bad);
    wait(&mut h, "the refusal", |a| {
        a.messages()
            .iter()
            .any(|m| m.starts_with("error") && m.contains("bad.nii"))
    });
    assert_eq!(
        h.state().opened().unwrap().title,
        rings.display().to_string()
    );
    let newest_first = [rings.clone(), cube.clone()];
    assert_eq!(h.state().recent().files(), &newest_first[..]);
    // The next run reads the list back and opens from it.
    drop(h);
    let mut h = open_phantom_recent(Some(store.clone()));
    assert_eq!(h.state().recent().files(), &newest_first[..]);
    h.get_by_label("File").click();
    h.run_steps(3);
    h.get_by_label("Open recent").click();
    h.run_steps(3);
    let dirname = dir
        .path()
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    h.get_by_label(&format!("cube.nii.gz — {dirname}")).click();
    wait_opened(&mut h, &cube, [24, 24, 24]);
    assert_eq!(
        voxflex_viewer::recent::RecentFiles::load(Some(store)).files(),
        &[cube, rings][..]
    );
}

#[test]
fn the_auto_lambda_box_writes_the_map_at_the_chosen_lambda_and_shows_it() {
    let mut h = open_phantom();
    seed_and_grow(&mut h);
    let fixed = h.state().rois()[0].info.clone();
    assert!(!fixed.lambda_auto);
    h.get_by_label(&format!("auto λ (map {})", fixed.id.0))
        .click();
    wait(&mut h, "the map at the automatic λ", |a| {
        a.rois()[0].info.lambda_auto && a.rois()[0].info.converged
    });
    let auto = h.state().rois()[0].info.clone();
    assert!(
        voxflex_opacity::auto_lambda::CANDIDATES.contains(&auto.params.lambda),
        "{auto:?}"
    );
    assert!(auto.voxels_above_half > 1000, "{auto:?}");
    // Written from the scan that chose λ, not grown.
    let (report, _) = h.state().rois()[0].last.expect("the map at auto λ");
    assert!(
        report.converged && report.steps == 0 && report.visits > 1000,
        "{report:?}"
    );
    h.get_by_label(&format!("λ = {:.2} (chosen)", auto.params.lambda));
    h.get_by_label(&format!(
        "from the λ scan, {} voxels ≥ ½, converged",
        auto.voxels_above_half
    ));
    // Unticked, the λ chosen stays, as a given one.
    h.get_by_label(&format!("auto λ (map {})", fixed.id.0))
        .click();
    wait(&mut h, "a fixed λ again", |a| {
        !a.rois()[0].info.lambda_auto
    });
    assert_eq!(h.state().rois()[0].info.params.lambda, auto.params.lambda);
}

#[test]
fn bounds_applied_in_the_panel_hold_the_map_within_them() {
    use voxflex_viewer::roi_bounds::BoundsEdit;
    let mut h = open_phantom();
    seed_and_grow(&mut h);
    let free = h.state().rois()[0].info.clone();
    h.get_by_label(&format!("bounds (map {})", free.id.0))
        .click();
    h.run_steps(2);
    let mut edit = BoundsEdit::of(free.limits);
    edit.distance_on = true;
    edit.distance_mm = 12.0;
    h.state_mut().roi_panel_mut().bounds.insert(free.id, edit);
    h.step();
    h.get_by_label(&format!("Apply bounds (map {})", free.id.0))
        .click();
    wait(&mut h, "the map within 12 mm of its seed", |a| {
        a.rois()[0].info.limits.max_distance_mm == Some(12.0) && a.rois()[0].info.converged
    });
    let bounded = &h.state().rois()[0].info;
    assert!(
        bounded.voxels_above_half < free.voxels_above_half / 4,
        "{bounded:?} vs {free:?}"
    );
}

#[test]
fn a_grab_drag_on_the_3d_view_picks_the_face_and_moves_the_volume() {
    let mut h = open_phantom();
    // The axial slice through the head's centre (z = 0).
    put_cursor(&mut h, DVec3::new(0.0, -60.0, 0.0));
    let before = h.state().slices().unwrap()[0].slice.image.pixels.clone();
    h.get_by_label("Grab").click();
    h.step();
    // The scene's camera looks at the face from the front (−y), its
    // target the head's centre: the image centre's ray runs along +y
    // through x = z = 0 and meets the skin at y = −112 mm.
    let rect = h.state().view3d_rect().expect("the 3D view drawn");
    let (from, to) = (
        rect.center(),
        rect.center() + egui::vec2(rect.width() / 8.0, 0.0),
    );
    h.hover_at(from);
    h.step();
    press(&h, from, true, Modifiers::NONE);
    h.step();
    for s in 1..=10 {
        h.hover_at(from + (to - from) * (s as f32 / 10.0));
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    // Held until the pick came back and the model stepped.
    wait(&mut h, "the grab's first step", |a| a.steps() > 0);
    press(&h, to, false, Modifiers::NONE);
    h.step();
    let p = h.state().last_3d_pick().expect("a point picked");
    // The first sample at or above the window floor (−160 HU) lies
    // between the skin's outer surface and the skull, 7 mm deeper.
    assert!((p - DVec3::new(0.0, -112.0, 0.0)).length() < 8.0, "{p}");
    wait(&mut h, "the moved face on the axial slice", |a| {
        let now = &a.slices().unwrap()[0].slice.image.pixels;
        now.len() == before.len() && now.iter().zip(&before).filter(|(x, y)| x != y).count() >= 5
    });
}
