//! voxflex-viewer: the desktop explorer on the host's
//! [`voxflex_runtime::session::Session`] — three linked slice views and a
//! ray-cast 3D view, ROI opacity maps grown from a click, and live
//! deformation with any deformation plugin. The session lives on a worker
//! thread ([`worker`]); the UI ([`app::ViewerApp`]) sends it commands and
//! draws the images it sends back, so the UI never waits on the pipeline.
//! See docs/VIEWER.md.

#![warn(missing_docs)]

pub mod adaptive;
pub mod app;
pub mod backend_panel;
pub mod bench;
pub mod cli;
pub mod compose;
pub mod dialogs;
pub mod file_menu;
pub mod gpu_image;
pub mod grab3d;
pub mod histogram;
pub mod model_panel;
pub mod open;
pub mod orientation;
pub mod param_form;
pub mod protocol;
pub mod recent;
pub mod render_info;
pub mod render_options;
pub mod render_panel;
pub mod roi_bounds;
pub mod roi_panel;
pub mod save_png;
pub mod scene_file;
pub mod screenshot;
pub mod slice_view;
pub mod tf_editor;
pub mod tf_points;
pub mod tools;
pub mod view3d;
pub mod window_level;
pub mod worker;
