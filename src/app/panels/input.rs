//! The photo and the settings every stage shares: field of view, output size and timing,
//! inpainting quality.

use super::{
    PanelContext, StagePanel, Tab, committed, frames_and_fps_ui, labelled, scene_image_ui,
};
use crate::app::viewport::{ViewTransform, image_view_ui};
use crate::stages::inpaint::InpaintPreset;
use eframe::egui::{self, Sense, Ui};

/// The Input tab.
#[derive(Default)]
pub struct InputPanel {
    transform: ViewTransform,
    /// The texture of a new photo shown before its first scene, by generation.
    early: Option<(u64, egui::TextureHandle)>,
}

impl StagePanel for InputPanel {
    fn tab(&self) -> Tab {
        Tab::Input
    }

    fn title(&self) -> &'static str {
        "Input"
    }

    fn view_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        if let Some(early) = cx.early_photo
            && cx.snapshot.is_none()
        {
            // A new photo, decoded: shown while its first scene builds.
            let texture = match &self.early {
                Some((g, t)) if *g == early.generation => t.clone(),
                _ => {
                    let t = ui.ctx().load_texture(
                        "input-early",
                        early.image.clone(),
                        egui::TextureOptions::LINEAR,
                    );
                    self.early = Some((early.generation, t.clone()));
                    t
                }
            };
            let (w, h) = early.working.size;
            image_view_ui(
                ui,
                texture.id(),
                [w, h],
                &mut self.transform,
                Sense::hover(),
            );
            return;
        }
        self.early = None;
        scene_image_ui(
            ui,
            cx,
            "input",
            &mut self.transform,
            Sense::hover(),
            |s| {
                let (w, h) = s.scene.input.rgb.size();
                [w, h]
            },
            |s| &s.display.input,
        );
    }

    fn inspector_ui(&mut self, ui: &mut Ui, cx: &mut PanelContext<'_>) {
        ui.heading("Photo");
        ui.label(cx.project.input.display().to_string());
        let working = cx
            .snapshot
            .map(|s| &s.scene.working)
            .or(cx.early_photo.map(|e| &e.working));
        if let Some(working) = working {
            let (w, h) = working.photo;
            ui.label(format!("{w} × {h} px"));
            if !working.is_photo() {
                let (ww, wh) = working.size;
                ui.label(format!("built at {ww} × {wh} px"))
                    .on_hover_text(working.to_string());
            }
        }
        let working = working.cloned();
        bars_ui(ui, cx, working);
        ui.separator();
        ui.heading("Camera");
        if let Some(v) = committed(ui, "hfov", cx.project.camera.hfov_deg, |ui, v| {
            ui.add(egui::Slider::new(v, 20.0..=120.0).text("field of view °"))
        }) {
            cx.edit("Field of view", |p| p.camera.hfov_deg = v);
        }
        ui.separator();
        ui.heading("Output");
        frames_and_fps_ui(ui, cx);
        ui.separator();
        ui.heading("Inpainting");
        let mut preset = cx.project.inpaint.preset;
        ui.horizontal(|ui| {
            for p in InpaintPreset::ALL {
                ui.selectable_value(&mut preset, p, p.name());
            }
        });
        if preset != cx.project.inpaint.preset {
            cx.edit("Inpaint quality", |p| p.inpaint.preset = preset);
        }
        if let Some(model) = super::model_picker(
            ui,
            "inpaint-model",
            crate::ml::ModelKind::Inpaint,
            cx.project.inpaint.model.as_deref(),
        ) {
            cx.edit("Inpaint model", |p| p.inpaint.model = model);
        }
        if let Some(v) = committed(ui, "seed", cx.project.inpaint.seed, |ui, v| {
            labelled(ui, "seed", egui::DragValue::new(v))
        }) {
            cx.edit("Inpaint seed", |p| p.inpaint.seed = v);
        }
        ui.separator();
        diffusion_ui(ui, cx);
        if let Some(s) = cx.snapshot {
            ui.separator();
            ui.label(format!("depth: {}", s.scene.depth_estimator));
            ui.label(format!("inpainter: {}", s.scene.inpainter));
            for w in &s.scene.warnings {
                ui.colored_label(ui.visuals().warn_fg_color, w);
            }
        }
    }
}

/// The "Crop bars" switch (one undo step; the edits placed on the picture move with
/// it, [`crate::project::Project::move_picture`]) and what it crops.
fn bars_ui(ui: &mut Ui, cx: &mut PanelContext<'_>, working: Option<crate::scene::WorkingSize>) {
    let mut crop = cx.project.photo.crop_bars;
    // Until the photo is read, where the bars are (and so where the edits go) is not known.
    ui.add_enabled(
        working.is_some(),
        egui::Checkbox::new(&mut crop, "Crop bars"),
    )
    .on_hover_text(
        "A film still's black letterbox or pillarbox, or the white padding an app adds to fit a \
         photo into a square, is not scene: cropped, the picture fills every frame instead of \
         bars moving with it",
    );
    let Some(working) = working else {
        return;
    };
    let found = working.found_bars;
    if crop != cx.project.photo.crop_bars {
        let [l, t, r, b] = working.bars;
        let photo = (working.photo.0 + l + r, working.photo.1 + t + b);
        let (from, to) = if crop {
            ([0; 4], found)
        } else {
            (found, [0; 4])
        };
        let size = [working.size.0, working.size.1];
        cx.edit("Crop bars", |p| {
            p.move_picture(photo, from, to, size);
            p.photo.crop_bars = crop;
        });
    }
    match (working.bars_cropped(), found != [0; 4]) {
        (Some(sides), _) => ui.label(format!("cropped: {sides}")),
        (None, true) => ui.label(format!(
            "found, kept: {}",
            crate::scene::WorkingSize::sides(found)
        )),
        (None, false) => ui.label("no bars found"),
    };
}

/// The diffusion fill's model, prompts and sampler (#45): each change one undo step.
fn diffusion_ui(ui: &mut Ui, cx: &mut PanelContext<'_>) {
    use crate::stages::inpaint::DiffusionSettings;
    use crate::stages::inpaint::schedule::SamplerKind;
    ui.heading("Generative fill");
    let installed: Vec<&'static str> = crate::models::models_dir()
        .map(|dir| {
            crate::models::DIFFUSION_CATALOGUE
                .iter()
                .filter(|e| crate::models::diffusion_installed(&dir, e).is_some())
                .map(|e| e.name)
                .collect()
        })
        .unwrap_or_default();
    // A folder as the file system names it (a project's relative path is joined to the
    // project's folder when loaded); a catalogue name as it is.
    let current = cx.project.inpaint.diffusion.as_ref().map(|d| {
        std::fs::canonicalize(&d.model)
            .unwrap_or_else(|_| d.model.clone())
            .display()
            .to_string()
    });
    let mut choice: Option<Option<String>> = None;
    ui.horizontal(|ui| {
        let name = ui.label("diffusion model");
        egui::ComboBox::from_id_salt("diffusion-model")
            .selected_text(current.as_deref().unwrap_or("none"))
            .show_ui(ui, |ui| {
                if ui.selectable_label(current.is_none(), "none").clicked() {
                    choice = Some(None);
                }
                for n in &installed {
                    if ui
                        .selectable_label(current.as_deref() == Some(*n), *n)
                        .clicked()
                    {
                        choice = Some(Some(n.to_string()));
                    }
                }
                if let Some(c) = current.as_deref().filter(|c| !installed.contains(c)) {
                    let _ = ui.selectable_label(true, c);
                }
            })
            .response
            .on_hover_text(
                "A Stable Diffusion inpainting model fills the outpainted margin and what each \
                 layer hides from a prompt; the quick fill shows first",
            )
            .labelled_by(name.id);
    });
    if let Some(text) = committed(
        ui,
        "diffusion-folder",
        current.clone().unwrap_or_default(),
        |ui, v| {
            labelled(
                ui,
                "diffusion model folder",
                egui::TextEdit::singleline(v).hint_text("a folder or a catalogue name"),
            )
        },
    ) {
        choice = Some((!text.trim().is_empty()).then(|| text.trim().to_string()));
    }
    if let Some(choice) = choice.filter(|c| *c != current) {
        let old = cx.project.inpaint.diffusion.clone();
        cx.edit("Diffusion model", |p| {
            p.inpaint.diffusion = choice.map(|m| DiffusionSettings {
                model: m.into(),
                ..old.unwrap_or_default()
            });
        });
    }
    if installed.is_empty() {
        ui.weak(
            "none installed: run `makeit4d models install sd2-inpainting` (about 2.6 GB), or \
             name a model folder",
        );
    }
    let Some(d) = cx.project.inpaint.diffusion.clone() else {
        return;
    };
    let text_field = |ui: &mut Ui, salt: &str, label: &str, value: String| {
        committed(ui, salt, value, |ui, v| {
            labelled(ui, label, egui::TextEdit::multiline(v).desired_rows(2))
        })
    };
    if let Some(v) = text_field(ui, "diffusion-prompt", "prompt", d.prompt.clone()) {
        cx.edit("Fill prompt", |p| {
            if let Some(d) = &mut p.inpaint.diffusion {
                d.prompt = v;
            }
        });
    }
    if let Some(v) = text_field(
        ui,
        "diffusion-negative",
        "negative prompt",
        d.negative_prompt.clone(),
    ) {
        cx.edit("Fill negative prompt", |p| {
            if let Some(d) = &mut p.inpaint.diffusion {
                d.negative_prompt = v;
            }
        });
    }
    let mut own = d.layers_prompt.is_some();
    if ui
        .checkbox(&mut own, "hidden regions have their own prompt")
        .changed()
    {
        let prompt = d.prompt.clone();
        cx.edit("Layers' prompt", |p| {
            if let Some(d) = &mut p.inpaint.diffusion {
                d.layers_prompt = own.then_some(prompt);
            }
        });
    }
    if let Some(lp) = d.layers_prompt.clone()
        && let Some(v) = text_field(ui, "diffusion-layers-prompt", "hidden regions' prompt", lp)
    {
        cx.edit("Layers' prompt", |p| {
            if let Some(d) = &mut p.inpaint.diffusion {
                d.layers_prompt = Some(v);
            }
        });
    }
    if let Some(v) = committed(ui, "diffusion-steps", d.steps, |ui, v| {
        labelled(
            ui,
            "steps",
            egui::DragValue::new(v).range(1..=crate::stages::inpaint::schedule::MAX_STEPS),
        )
    }) {
        cx.edit("Fill steps", |p| {
            if let Some(d) = &mut p.inpaint.diffusion {
                d.steps = v;
            }
        });
    }
    if let Some(v) = committed(ui, "diffusion-guidance", d.guidance, |ui, v| {
        labelled(
            ui,
            "guidance",
            egui::DragValue::new(v).range(0.0..=100.0).speed(0.1),
        )
    }) {
        cx.edit("Fill guidance", |p| {
            if let Some(d) = &mut p.inpaint.diffusion {
                d.guidance = v;
            }
        });
    }
    let mut sampler = d.scheduler;
    ui.horizontal(|ui| {
        let name = ui.label("sampler");
        egui::ComboBox::from_id_salt("diffusion-sampler")
            .selected_text(sampler.name())
            .show_ui(ui, |ui| {
                for k in [
                    SamplerKind::Ddim,
                    SamplerKind::EulerAncestral,
                    SamplerKind::DpmSolver2m,
                    SamplerKind::Lcm,
                ] {
                    ui.selectable_value(&mut sampler, k, k.name());
                }
            })
            .response
            .labelled_by(name.id);
    });
    if sampler != d.scheduler {
        cx.edit("Fill sampler", |p| {
            if let Some(d) = &mut p.inpaint.diffusion {
                d.scheduler = sampler;
            }
        });
    }
    ui.weak(
        "The quick fill shows first; the diffusion fill follows in the background (the status \
         bar counts windows and steps; Cancel stops it). On a CPU a 512-pixel window takes \
         minutes: about 5 s a step.",
    );
}
