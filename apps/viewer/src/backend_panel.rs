//! The *Backend* box of the status bar: where the session computes (CPU,
//! GPU or auto), the adapter, a warning when the GPU path runs on a
//! software adapter, and a failed switch's error, inline.

use crate::protocol::Command;
use egui::{Color32, RichText};
use std::sync::Arc;
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::gpu_context::{AdapterSummary, WgpuService};
use voxflex_runtime::session::Session;

/// Shown when the GPU path's adapter is a software rasteriser (lavapipe,
/// llvmpipe, SwiftShader, WARP).
pub const SOFTWARE_WARNING: &str = "software adapter: GPU path is slower than the CPU path here";

/// The choices in the combo box, in order.
pub const CHOICES: [(BackendChoice, &str); 3] = [
    (BackendChoice::Cpu, "CPU"),
    (BackendChoice::Gpu, "GPU"),
    (BackendChoice::Auto, "auto"),
];

/// Where the session computes, as the worker reports it after opening and
/// after each switch.
#[derive(Clone, Debug, PartialEq)]
pub struct BackendStatus {
    /// The choice in force.
    pub choice: BackendChoice,
    /// The adapter computing now; `None` on the CPU path.
    pub computing: Option<AdapterSummary>,
    /// The adapter a `GPU` choice computes on: the device the viewer shares
    /// with the session; `None` when there is none (the session then opens
    /// its own).
    pub shared: Option<AdapterSummary>,
}

impl BackendStatus {
    /// `session`'s backend after `choice`, with the UI's `shared` device.
    pub fn of(session: &Session, choice: BackendChoice, shared: Option<&Arc<WgpuService>>) -> Self {
        Self {
            choice,
            computing: session.wgpu().map(|g| g.info()),
            shared: shared.map(|g| g.info()),
        }
    }

    /// The adapter the GPU path uses: the one computing, else the shared one.
    pub fn gpu_adapter(&self) -> Option<&AdapterSummary> {
        self.computing.as_ref().or(self.shared.as_ref())
    }
}

/// [`SOFTWARE_WARNING`] when the GPU path's adapter is a software one
/// (whether or not it computes now: under `auto` it is why the CPU was
/// taken), else `None`.
pub fn software_warning(status: &BackendStatus) -> Option<&'static str> {
    status
        .gpu_adapter()
        .filter(|a| a.software)
        .map(|_| SOFTWARE_WARNING)
}

/// The box's state.
#[derive(Debug, Default)]
pub struct BackendPanel {
    /// As last reported; `None` until the session is open.
    pub status: Option<BackendStatus>,
    /// The last switch's error (no adapter, a model without a GPU path…).
    pub error: Option<String>,
    /// A switch sent and not answered yet.
    pending: Option<BackendChoice>,
}

impl BackendPanel {
    /// The worker's report: the switch (if any) is done.
    pub fn on_status(&mut self, status: BackendStatus) {
        self.status = Some(status);
        self.error = None;
        self.pending = None;
    }

    /// A switch failed; the session stays where it was.
    pub fn on_error(&mut self, error: String) {
        self.error = Some(error);
        self.pending = None;
    }

    /// Draws the box in a row (the status bar): the combo box, the adapter,
    /// the warning and the error; returns the switch to send when the
    /// combo box changed.
    pub fn ui(&mut self, ui: &mut egui::Ui) -> Option<Command> {
        let status = self.status.clone()?;
        let mut choice = self.pending.unwrap_or(status.choice);
        let before = choice;
        egui::ComboBox::from_label("Backend")
            .selected_text(choice_name(choice))
            .show_ui(ui, |ui| {
                for (c, n) in CHOICES {
                    ui.selectable_value(&mut choice, c, n);
                }
            });
        let mut command = None;
        if choice != before {
            self.pending = Some(choice);
            command = Some(Command::SetBackend(choice));
        }
        let adapter = match (&status.computing, &status.shared) {
            (Some(a), _) => a.name.clone(),
            (None, Some(g)) => format!("cpu (rayon); GPU: {}", g.name),
            (None, None) => "cpu (rayon)".into(),
        };
        let hover = status
            .gpu_adapter()
            .map_or("no GPU adapter opened".into(), |a| a.to_string());
        ui.label(adapter).on_hover_text(hover);
        if self.pending.is_some() {
            ui.label("switching…");
        }
        if let Some(w) = software_warning(&status) {
            ui.label(RichText::new(w).color(Color32::from_rgb(230, 160, 40)));
        }
        if let Some(e) = &self.error {
            ui.label(RichText::new(e).color(Color32::from_rgb(220, 60, 60)));
        }
        ui.separator();
        command
    }
}

/// The combo box's name of `c`.
fn choice_name(c: BackendChoice) -> &'static str {
    CHOICES
        .iter()
        .find(|(b, _)| *b == c)
        .map_or("?", |(_, n)| n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use eframe::wgpu;

    fn info(name: &str, device_type: wgpu::DeviceType) -> AdapterSummary {
        AdapterSummary::from_info(&wgpu::AdapterInfo {
            name: name.into(),
            vendor: 0,
            device: 0,
            device_type,
            device_pci_bus_id: String::new(),
            driver: String::new(),
            driver_info: String::new(),
            backend: wgpu::Backend::Vulkan,
            subgroup_min_size: 4,
            subgroup_max_size: 4,
            transient_saves_memory: None,
            limit_bucket: None,
        })
    }

    fn status(computing: Option<AdapterSummary>, shared: Option<AdapterSummary>) -> BackendStatus {
        BackendStatus {
            choice: BackendChoice::Gpu,
            computing,
            shared,
        }
    }

    /// The box in a harness; the commands it returned so far.
    fn harness(
        panel: BackendPanel,
    ) -> egui_kittest::Harness<'static, (BackendPanel, Vec<Command>)> {
        egui_kittest::Harness::builder().build_ui_state(
            |ui, (panel, sent): &mut (BackendPanel, Vec<Command>)| {
                ui.horizontal(|ui| sent.extend(panel.ui(ui)));
            },
            (panel, vec![]),
        )
    }

    #[test]
    fn the_combo_box_asks_for_a_switch_and_a_failed_one_shows_inline() {
        let lavapipe = info("llvmpipe (LLVM 15.0.6, 256 bits)", wgpu::DeviceType::Cpu);
        let mut panel = BackendPanel::default();
        panel.on_status(BackendStatus {
            choice: BackendChoice::Cpu,
            computing: None,
            shared: Some(lavapipe),
        });
        let mut h = harness(panel);
        use egui_kittest::kittest::Queryable;
        assert!(h.query_by_label_contains("GPU: llvmpipe").is_some());
        assert!(h.query_by_label(SOFTWARE_WARNING).is_some());
        h.get_by_role_and_label(egui::accesskit::Role::ComboBox, "Backend")
            .click();
        h.run();
        h.get_by_label("GPU").click();
        h.run();
        let sent = &h.state().1;
        assert!(
            matches!(sent.as_slice(), [Command::SetBackend(BackendChoice::Gpu)]),
            "{sent:?}"
        );
        assert!(h.query_by_label("switching…").is_some());
        h.state_mut().0.on_error("gpu: no GPU adapter found".into());
        h.run();
        assert!(h.query_by_label("gpu: no GPU adapter found").is_some());
        assert!(h.query_by_label("switching…").is_none());
    }

    #[test]
    fn software_adapters_get_the_warning_and_hardware_ones_do_not() {
        let lavapipe = info("llvmpipe (LLVM 15.0.6, 256 bits)", wgpu::DeviceType::Cpu);
        let swiftshader = info("SwiftShader Device (Subzero)", wgpu::DeviceType::Other);
        let warp = info("Microsoft Basic Render Driver", wgpu::DeviceType::Other);
        let nvidia = info("NVIDIA H200", wgpu::DeviceType::DiscreteGpu);
        for soft in [&lavapipe, &swiftshader, &warp] {
            assert_eq!(
                software_warning(&status(Some(soft.clone()), None)),
                Some(SOFTWARE_WARNING),
                "{}",
                soft.name
            );
            // On the CPU the shared adapter is the one a GPU choice takes.
            assert_eq!(
                software_warning(&status(None, Some(soft.clone()))),
                Some(SOFTWARE_WARNING)
            );
        }
        assert_eq!(software_warning(&status(Some(nvidia.clone()), None)), None);
        assert_eq!(software_warning(&status(None, Some(nvidia.clone()))), None);
        assert_eq!(software_warning(&status(None, None)), None);
        // The adapter computing decides over the shared one.
        assert_eq!(
            software_warning(&status(Some(nvidia), Some(lavapipe))),
            None
        );
    }
}
