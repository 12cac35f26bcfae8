//! The timeline under the views: play/pause, scrubbing, loop, keyframe markers (select,
//! delete, interpolation and ease per key) and a strip coloured by each frame's hole fraction
//! (upper half) and synthesised share, with the relief no depth cue vouches for that the move
//! shifts (lower half).

pub use super::context::TimelineState;

use super::context::{PanelContext, Request};
use crate::path::{CameraPath, Ease, Interpolation};
use eframe::egui::{self, Color32, Sense, Stroke, Ui, pos2, vec2};

/// Key frames of the path (none for a preset).
pub fn key_frames(path: &CameraPath) -> Vec<f64> {
    match path {
        CameraPath::Keyframes(k) => k.keys.iter().map(|k| k.frame).collect(),
        CameraPath::Preset(_) => Vec::new(),
    }
}

/// Draws the timeline.
pub fn timeline_ui(ui: &mut Ui, cx: &mut PanelContext<'_>) {
    let frames = cx.project.output.frames.max(1);
    let fps = cx.project.output.fps;
    ui.horizontal(|ui| {
        let play = if cx.timeline.playing { "Pause" } else { "Play" };
        if ui
            .button(play)
            .on_hover_text("Play or pause the preview (Space)")
            .clicked()
        {
            toggle_play(cx, frames);
        }
        if ui.button("|<").on_hover_text("First frame").clicked() {
            cx.timeline.seek(0);
        }
        ui.checkbox(&mut cx.timeline.looping, "Loop");
        let mut f = cx.timeline.frame;
        let label = ui.label("Frame");
        if ui
            .add(egui::DragValue::new(&mut f).range(0..=frames - 1))
            .labelled_by(label.id)
            .changed()
        {
            cx.timeline.seek(f);
        }
        ui.label(format!(
            "/ {}  ·  {:.2} s at {fps} fps",
            frames - 1,
            f as f32 / fps
        ));
        ui.separator();
        if ui
            .button("Add key (I)")
            .on_hover_text("Add a keyframe at this frame with the current preview view (I)")
            .clicked()
        {
            cx.requests.push(Request::AddKeyframe);
        }
        keyframe_controls_ui(ui, cx);
    });
    scrub_bar_ui(ui, cx, frames);
    hole_strip_ui(ui, cx, frames);
}

fn toggle_play(cx: &mut PanelContext<'_>, frames: usize) {
    let t = &mut *cx.timeline;
    t.playing = !t.playing;
    if t.playing && t.frame + 1 >= frames && !t.looping {
        t.seek(0);
    }
    t.clock = t.frame as f64;
}

/// Delete / interpolation / ease of the selected key.
fn keyframe_controls_ui(ui: &mut Ui, cx: &mut PanelContext<'_>) {
    let CameraPath::Keyframes(path) = &cx.project.camera.path else {
        return;
    };
    let Some(i) = cx.timeline.selected_key.filter(|&i| i < path.keys.len()) else {
        return;
    };
    let key = path.keys[i];
    ui.separator();
    ui.label(format!("key {} at frame {}", i + 1, key.frame));
    let mut interpolation = key.interpolation;
    egui::ComboBox::from_label("interpolation")
        .selected_text(interpolation.name())
        .show_ui(ui, |ui| {
            for v in Interpolation::ALL {
                ui.selectable_value(&mut interpolation, v, v.name());
            }
        });
    let mut ease = key.ease;
    egui::ComboBox::from_label("ease")
        .selected_text(ease.name())
        .show_ui(ui, |ui| {
            for v in Ease::ALL {
                ui.selectable_value(&mut ease, v, v.name());
            }
        });
    if interpolation != key.interpolation {
        cx.edit("Key interpolation", |p| {
            set_key(p, i, |k| k.interpolation = interpolation)
        });
    }
    if ease != key.ease {
        cx.edit("Key ease", |p| set_key(p, i, |k| k.ease = ease));
    }
    if ui.button("Delete key").clicked() {
        delete_key(cx, i);
    }
}

/// Deletes key `i` (a path needs one key at least: deleting the last one goes back to the
/// preset the keys were made from, or the default one).
pub fn delete_key(cx: &mut PanelContext<'_>, i: usize) {
    cx.edit("Delete keyframe", |p| {
        if let CameraPath::Keyframes(path) = &mut p.camera.path
            && i < path.keys.len()
        {
            path.keys.remove(i);
            if path.keys.is_empty() {
                p.camera.path = path
                    .from_preset
                    .map_or_else(CameraPath::default, CameraPath::Preset);
            }
        }
    });
    cx.timeline.selected_key = None;
}

fn set_key(p: &mut crate::project::Project, i: usize, f: impl FnOnce(&mut crate::path::Keyframe)) {
    if let CameraPath::Keyframes(path) = &mut p.camera.path
        && let Some(k) = path.keys.get_mut(i)
    {
        f(k);
    }
}

/// The frame ruler with keyframe diamonds and the playhead; click or drag to scrub.
fn scrub_bar_ui(ui: &mut Ui, cx: &mut PanelContext<'_>, frames: usize) {
    let (rect, response) =
        ui.allocate_exact_size(vec2(ui.available_width(), 26.0), Sense::click_and_drag());
    let painter = ui.painter_at(rect);
    let visuals = ui.visuals();
    painter.rect_filled(rect, 3.0, visuals.extreme_bg_color);
    let x_of = |f: f64| {
        rect.left() + 8.0 + (rect.width() - 16.0) * (f / (frames.max(2) - 1) as f64) as f32
    };
    let frame_of = |x: f32| {
        (((x - rect.left() - 8.0) / (rect.width() - 16.0)).clamp(0.0, 1.0)
            * (frames.max(2) - 1) as f32)
            .round() as usize
    };
    // Ticks every 10 frames (or coarser).
    let step = [1, 5, 10, 25, 50, 100, 250, 500, 1000]
        .into_iter()
        .find(|s| (rect.width() / (frames as f32 / *s as f32)) > 30.0)
        .unwrap_or(5000);
    for f in (0..frames).step_by(step) {
        let x = x_of(f as f64);
        painter.line_segment(
            [pos2(x, rect.bottom() - 6.0), pos2(x, rect.bottom())],
            Stroke::new(1.0, visuals.weak_text_color()),
        );
    }
    // Keyframes.
    let keys = key_frames(&cx.project.camera.path);
    let mut clicked_key = None;
    for (i, &k) in keys.iter().enumerate() {
        let centre = pos2(x_of(k), rect.center().y);
        let selected = cx.timeline.selected_key == Some(i);
        let r = if selected { 7.0 } else { 5.5 };
        let diamond = vec![
            centre + vec2(0.0, -r),
            centre + vec2(r, 0.0),
            centre + vec2(0.0, r),
            centre + vec2(-r, 0.0),
        ];
        let fill = if selected {
            Color32::from_rgb(255, 200, 60)
        } else {
            Color32::from_rgb(230, 170, 40)
        };
        painter.add(egui::Shape::convex_polygon(
            diamond,
            fill,
            Stroke::new(1.0, Color32::BLACK),
        ));
        if let Some(p) = response.interact_pointer_pos()
            && response.clicked()
            && (p - centre).length() <= r + 3.0
        {
            clicked_key = Some(i);
        }
    }
    // Playhead.
    let x = x_of(cx.timeline.frame as f64);
    painter.line_segment(
        [pos2(x, rect.top()), pos2(x, rect.bottom())],
        Stroke::new(2.0, Color32::from_rgb(255, 80, 80)),
    );
    if let Some(i) = clicked_key {
        cx.timeline.selected_key = Some(i);
        cx.timeline.seek(keys[i].round().max(0.0) as usize);
    } else if let Some(p) = response.interact_pointer_pos()
        && (response.dragged() || response.clicked())
    {
        cx.timeline.seek(frame_of(p.x).min(frames - 1));
    }
}

/// Colour of the holes half of a strip cell: grey-green at none, red at the threshold.
pub const HOLES_COLOUR: Color32 = Color32::from_rgb(235, 60, 50);
/// Colour of the synthesised half of a strip cell: grey-blue at none, violet at the threshold.
pub const SYNTH_COLOUR: Color32 = Color32::from_rgb(190, 90, 255);

/// `base` → `full` by `t ∈ [0, 1]`.
fn ramp(base: Color32, full: Color32, t: f32) -> Color32 {
    let t = t.clamp(0.0, 1.0);
    let mix = |a: u8, b: u8| (a as f32 + (b as f32 - a as f32) * t).round() as u8;
    Color32::from_rgb(
        mix(base.r(), full.r()),
        mix(base.g(), full.g()),
        mix(base.b(), full.b()),
    )
}

/// The two colours of frame `f`'s strip cell (holes above, synthesised below), by each
/// fraction over its threshold, from the path diagnostics; without them, the holes of the
/// previewed frames (red at 5 %) and grey.
pub fn strip_colours(
    timeline: &TimelineState,
    thresholds: (f32, f32),
    f: usize,
) -> Option<(Color32, Color32)> {
    let grey = Color32::from_gray(60);
    let scale = |v: f32, threshold: f32| {
        if threshold > 0.0 {
            v / threshold
        } else if v > 0.0 {
            1.0
        } else {
            0.0
        }
    };
    if let Some((_, d)) = &timeline.diagnostics {
        let frame = d.frames.get(f)?;
        return Some((
            ramp(
                Color32::from_rgb(60, 110, 70),
                HOLES_COLOUR,
                scale(frame.hole_fraction, thresholds.0),
            ),
            ramp(
                Color32::from_rgb(60, 80, 110),
                SYNTH_COLOUR,
                scale(frame.synthesised_or_unsure(), thresholds.1),
            ),
        ));
    }
    let h = *timeline.hole_fractions.get(&f)?;
    Some((
        ramp(Color32::from_rgb(60, 210, 60), HOLES_COLOUR, h / 0.05),
        grey,
    ))
}

/// One cell per frame: its upper half by hole fraction, its lower half by synthesised share
/// plus the share over unsure depth (from the path diagnostics; grey: not measured yet). Hovering names the frame's numbers.
fn hole_strip_ui(ui: &mut Ui, cx: &mut PanelContext<'_>, frames: usize) {
    let (rect, response) = ui.allocate_exact_size(vec2(ui.available_width(), 14.0), Sense::hover());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 0.0, Color32::from_gray(60));
    let inner_left = rect.left() + 8.0;
    let inner_width = rect.width() - 16.0;
    let cell = inner_width / frames as f32;
    let t = cx.project.camera.diagnostics;
    let thresholds = (t.hole_threshold, t.synth_threshold);
    let mid = rect.center().y;
    for f in 0..frames {
        let Some((holes, synth)) = strip_colours(cx.timeline, thresholds, f) else {
            continue;
        };
        let x = inner_left + f as f32 * cell;
        let x1 = x + cell.max(1.0);
        painter.rect_filled(
            egui::Rect::from_min_max(pos2(x, rect.top()), pos2(x1, mid)),
            0.0,
            holes,
        );
        painter.rect_filled(
            egui::Rect::from_min_max(pos2(x, mid), pos2(x1, rect.bottom())),
            0.0,
            synth,
        );
    }
    let hovered = response.hover_pos().map(|p| {
        (((p.x - inner_left) / cell).floor().max(0.0) as usize).min(frames.saturating_sub(1))
    });
    let diagnostics = cx.timeline.diagnostics.as_ref().map(|(_, d)| d);
    response.on_hover_ui(|ui| {
        ui.label(egui::RichText::new("holes").color(HOLES_COLOUR).strong());
        ui.label(format!(
            "upper half: the share of the frame nothing covers (red at {:.1} %)",
            100.0 * thresholds.0
        ));
        ui.label(
            egui::RichText::new("synthesised")
                .color(SYNTH_COLOUR)
                .strong(),
        );
        ui.label(format!(
            "lower half: the share showing inpainted or outpainted content, or relief no depth \
             cue vouches for moved more than {} px (violet at {:.1} %)",
            crate::path::diagnostics::UNSURE_SHIFT_PX,
            100.0 * thresholds.1
        ));
        match (hovered, diagnostics) {
            (Some(f), Some(d)) if f < d.frames.len() => {
                let m = d.frames[f];
                ui.label(format!(
                    "frame {f}: {:.1} % holes, {:.1} % synthesised, {:.1} % over unsure depth",
                    100.0 * m.hole_fraction,
                    100.0 * m.inpainted_fraction,
                    100.0 * m.unsure_fraction
                ));
            }
            _ => {
                ui.label("grey: not measured yet");
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn playback_wraps_or_stops() {
        let mut t = TimelineState {
            playing: true,
            looping: true,
            ..Default::default()
        };
        assert!(t.advance(0.5, 10.0, 8));
        assert_eq!(t.frame, 5);
        t.advance(0.5, 10.0, 8);
        assert_eq!(t.frame, 2);
        t.looping = false;
        t.advance(10.0, 10.0, 8);
        assert_eq!(t.frame, 7);
        assert!(!t.playing);
        assert!(!t.advance(1.0, 10.0, 8));
    }

    #[test]
    fn a_frame_that_follows_the_preview_stays_while_the_clock_runs() {
        let mut t = TimelineState {
            playing: true,
            looping: true,
            follows_preview: true,
            ..Default::default()
        };
        assert!(!t.advance(0.5, 10.0, 8));
        assert_eq!((t.frame, t.clock_frame(8)), (0, 5));
        // The app sets the frame when the picture for it arrives.
        t.frame = t.clock_frame(8);
        t.advance(0.25, 10.0, 8);
        assert_eq!((t.frame, t.clock_frame(8)), (5, 7));
    }
}
