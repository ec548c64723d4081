//! Plugin discovery and checked loading.
//!
//! Search order (first match wins): the scene's `plugin_dirs`, then every
//! directory in `VOXFLEX_PLUGIN_PATH` (`:`-separated; `;` on Windows), then
//! the running executable's own directory — so `target/release/voxflex`
//! finds `target/release/libvoxflex_*.so`.
//!
//! A plugin named `mass-spring` lives in `libvoxflex_mass_spring.so`
//! (`voxflex_mass_spring.dll` on Windows, `.dylib` on macOS). Only the files
//! of plugins a scene names are opened. Libraries are never unloaded: their
//! code may still be referenced by thread pools or statics.

use std::path::{Path, PathBuf};
use voxflex_abi::ffi::{
    ActuatorVTable, CAPABILITY_CPU, CAPABILITY_GPU, DeformationVTable, PLUGIN_MAGIC, PluginEntry,
    PluginHeader, PluginKind, RendererVTable,
};
use voxflex_core::error::ModelError;

/// Loading a plugin failed.
#[derive(Debug, thiserror::Error)]
pub enum PluginError {
    /// No file for the named plugin in any search directory.
    #[error(
        "plugin `{name}` not found: looked for {file} in {searched}; build it (`cargo build --release`) or add its directory to `plugin_dirs` / VOXFLEX_PLUGIN_PATH"
    )]
    NotFound {
        /// Plugin name.
        name: String,
        /// File name looked for.
        file: String,
        /// The directories searched, joined.
        searched: String,
    },
    /// The dynamic library could not be opened or lacks the entry symbol.
    #[error("{path}: {message}")]
    Open {
        /// Library path.
        path: PathBuf,
        /// Loader message.
        message: String,
    },
    /// The plugin was built against another ABI.
    #[error(
        "{path}: plugin ABI mismatch: the plugin was built for ABI v{plugin_version} (layout {plugin_hash:016x}), this host speaks ABI v{host_version} (layout {host_hash:016x}); rebuild the plugin against this voxflex"
    )]
    AbiMismatch {
        /// Library path.
        path: PathBuf,
        /// ABI version in the plugin.
        plugin_version: u32,
        /// Layout hash in the plugin.
        plugin_hash: u64,
        /// ABI version of the host.
        host_version: u32,
        /// Layout hash of the host.
        host_hash: u64,
    },
    /// The library's declaration is malformed or inconsistent.
    #[error("{path}: {message}")]
    Invalid {
        /// Library path.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// A loaded, checked plugin library.
#[derive(Clone, Debug)]
pub struct LoadedPlugin {
    /// Library path.
    pub path: PathBuf,
    /// Declared name.
    pub name: String,
    /// Declared semver.
    pub version: String,
    /// Declared one-line description.
    pub description: String,
    /// What the plugin is.
    pub kind: PluginKind,
    /// `CAPABILITY_*` bits.
    pub capabilities: u32,
    /// ABI version (equal to the host's).
    pub abi_version: u32,
    /// The deformation vtable (kind = deformation).
    pub deformation: Option<&'static DeformationVTable>,
    /// The renderer vtable (kind = renderer).
    pub renderer: Option<&'static RendererVTable>,
    /// The actuator vtable (kind = actuator).
    pub actuator: Option<&'static ActuatorVTable>,
    /// The keys of its parameter table, as the plugin declared them
    /// ([`crate::param_schema`]).
    pub params: crate::param_schema::ParamSchema,
}

impl LoadedPlugin {
    /// `"cpu, gpu"`-style capability list.
    pub fn capability_names(&self) -> String {
        let mut v = vec![];
        if self.capabilities & CAPABILITY_CPU != 0 {
            v.push("cpu");
        }
        if self.capabilities & CAPABILITY_GPU != 0 {
            v.push("gpu");
        }
        v.join(", ")
    }

    /// A parameter table (TOML text) against the plugin's declared schema:
    /// every unknown key, missing key, wrong type and value out of range at
    /// once — the plugin's `create`, which the host calls next, stops at its
    /// first. A table that is not TOML is left to `create`, which names the
    /// error. Every path that creates a plugin instance calls this first,
    /// so `validate`, `run` and a session give the same message.
    pub fn check_params(&self, params_toml: &str) -> Result<(), ModelError> {
        let Ok(table) = params_toml.parse::<toml::Table>() else {
            return Ok(());
        };
        let issues = self.params.check(&table);
        if issues.is_empty() {
            return Ok(());
        }
        Err(ModelError(format!(
            "plugin `{}` parameters: {} (`voxflex plugins --params {}` lists every key with its \
             type, unit, range and default)",
            self.name,
            issues.join("; "),
            self.name
        )))
    }

    /// Lower-case kind name.
    pub fn kind_name(&self) -> &'static str {
        match self.kind {
            PluginKind::Deformation => "deformation",
            PluginKind::Renderer => "renderer",
            PluginKind::Actuator => "actuator",
        }
    }
}

/// File name of the library holding plugin `name` on this platform.
pub fn library_file_name(name: &str) -> String {
    format!(
        "{}voxflex_{}{}",
        std::env::consts::DLL_PREFIX,
        name.replace('-', "_"),
        std::env::consts::DLL_SUFFIX
    )
}

/// The search path: `scene_dirs`, then `VOXFLEX_PLUGIN_PATH`, then the
/// executable's directory. Missing directories are kept (they are reported
/// in "not found" errors) but cost nothing.
pub fn search_path(scene_dirs: &[PathBuf]) -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = scene_dirs.to_vec();
    if let Some(env) = std::env::var_os("VOXFLEX_PLUGIN_PATH") {
        dirs.extend(std::env::split_paths(&env).filter(|p| !p.as_os_str().is_empty()));
    }
    if let Ok(exe) = std::env::current_exe()
        && let Some(dir) = exe.parent()
    {
        dirs.push(dir.to_path_buf());
    }
    dirs
}

/// Finds and loads plugin `name` from the first directory of `dirs` that has it.
pub fn load_by_name(name: &str, dirs: &[PathBuf]) -> Result<LoadedPlugin, PluginError> {
    let file = library_file_name(name);
    let Some(path) = dirs.iter().map(|d| d.join(&file)).find(|p| p.is_file()) else {
        return Err(PluginError::NotFound {
            name: name.to_owned(),
            file,
            searched: dirs
                .iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
        });
    };
    let plugin = load_file(&path)?;
    if plugin.name != name {
        return Err(PluginError::Invalid {
            path,
            message: format!(
                "declares the name `{}`, but the scene asked for `{name}`",
                plugin.name
            ),
        });
    }
    Ok(plugin)
}

/// Every plugin library file (`libvoxflex_*.so`) in `dirs`, in search
/// order (sorted by name within a directory), each file once even when a
/// directory appears twice in the search path.
fn library_files(dirs: &[PathBuf]) -> Vec<PathBuf> {
    let prefix = format!("{}voxflex_", std::env::consts::DLL_PREFIX);
    let suffix = std::env::consts::DLL_SUFFIX;
    let mut seen = std::collections::BTreeSet::new();
    let mut out = vec![];
    for dir in dirs {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with(&prefix) && n.ends_with(suffix))
            })
            .collect();
        files.sort();
        for f in files {
            let key = std::fs::canonicalize(&f).unwrap_or_else(|_| f.clone());
            if seen.insert(key) {
                out.push(f);
            }
        }
    }
    out
}

/// One plugin name of a [`PluginListing`].
#[derive(Debug)]
pub struct ListedPlugin {
    /// The library [`load_by_name`] opens for this name, or, when none
    /// would (`loads` false), the first library that declares the name.
    pub plugin: LoadedPlugin,
    /// Whether `plugin` is what a scene naming this plugin gets.
    pub loads: bool,
    /// Other libraries on the search path that declare the same name; a
    /// scene never gets them while `plugin.path` is there.
    pub shadowed: Vec<PathBuf>,
}

/// What `voxflex plugins` shows: every library on the search path, loaded
/// and checked, one entry per declared plugin name.
#[derive(Debug, Default)]
pub struct PluginListing {
    /// Plugins by declared name, in search order.
    pub plugins: Vec<ListedPlugin>,
    /// Libraries that could not be loaded, with why.
    pub refused: Vec<PluginError>,
}

/// Loads every plugin library in `dirs` (see [`PluginListing`]). A copy of
/// a plugin — under another file name, or in a later directory — is listed
/// once under its declared name with the path that wins and the paths it
/// shadows, never as a second plugin.
pub fn list(dirs: &[PathBuf]) -> PluginListing {
    let mut listing = PluginListing::default();
    let mut by_name: Vec<(String, Vec<LoadedPlugin>)> = vec![];
    for f in library_files(dirs) {
        match load_file(&f) {
            Ok(p) => match by_name.iter_mut().find(|(n, _)| *n == p.name) {
                Some((_, v)) => v.push(p),
                None => by_name.push((p.name.clone(), vec![p])),
            },
            Err(e) => listing.refused.push(e),
        }
    }
    let canonical = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    for (name, mut found) in by_name {
        let file = library_file_name(&name);
        let winner = dirs
            .iter()
            .map(|d| d.join(&file))
            .find(|p| p.is_file())
            .map(|p| canonical(&p));
        let pos = found
            .iter()
            .position(|p| Some(canonical(&p.path)) == winner);
        let plugin = found.remove(pos.unwrap_or(0));
        listing.plugins.push(ListedPlugin {
            plugin,
            loads: pos.is_some(),
            shadowed: found.into_iter().map(|p| p.path).collect(),
        });
    }
    listing
}

/// Opens one library, checks its header and reads its declaration.
pub fn load_file(path: &Path) -> Result<LoadedPlugin, PluginError> {
    let open_err = |message: String| PluginError::Open {
        path: path.to_path_buf(),
        message,
    };
    // SAFETY: loading a library runs its initialisers; voxflex plugins have
    // none beyond Rust statics. This is the trust boundary of any plugin host.
    let lib = unsafe { libloading::Library::new(path) }.map_err(|e| open_err(e.to_string()))?;
    // Never unloaded (see the module docs).
    let lib: &'static libloading::Library = Box::leak(Box::new(lib));
    let symbol = format!("{}\0", voxflex_abi::ENTRY_SYMBOL);
    // SAFETY: the symbol type is the ABI's frozen entry signature.
    let entry: libloading::Symbol<'static, PluginEntry> = unsafe { lib.get(symbol.as_bytes()) }
        .map_err(|e| {
            open_err(format!(
                "not a voxflex plugin: no `{}` symbol ({e})",
                voxflex_abi::ENTRY_SYMBOL
            ))
        })?;
    // SAFETY: calling the entry point, which returns a pointer to a static.
    let header_ptr = unsafe { entry() };
    if header_ptr.is_null() {
        return Err(open_err("entry point returned a null header".into()));
    }
    // SAFETY: the header layout is frozen across ABI versions.
    let header: &'static PluginHeader = unsafe { &*header_ptr };
    if header.magic != PLUGIN_MAGIC {
        return Err(open_err(
            "entry point returned a header without the voxflex magic number".into(),
        ));
    }
    if header.abi_version != voxflex_abi::ABI_VERSION
        || header.layout_hash != voxflex_abi::LAYOUT_HASH
    {
        return Err(PluginError::AbiMismatch {
            path: path.to_path_buf(),
            plugin_version: header.abi_version,
            plugin_hash: header.layout_hash,
            host_version: voxflex_abi::ABI_VERSION,
            host_hash: voxflex_abi::LAYOUT_HASH,
        });
    }
    if header.declaration.is_null() {
        return Err(open_err("header has no declaration".into()));
    }
    // SAFETY: version and layout match, so the declaration has our layout.
    let decl = unsafe { &*header.declaration };
    // SAFETY: static strings in the library.
    let (name, version, description) = unsafe {
        (
            decl.name.to_string_lossy(),
            decl.version.to_string_lossy(),
            decl.description.to_string_lossy(),
        )
    };
    let invalid = |message: String| PluginError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    if name.is_empty() {
        return Err(invalid("declares an empty name".into()));
    }
    let kind = PluginKind::from_code(decl.kind)
        .ok_or_else(|| invalid(format!("declares unknown plugin kind code {}", decl.kind)))?;
    let (mut deformation, mut renderer, mut actuator) = (None, None, None);
    match kind {
        PluginKind::Deformation if decl.deformation.is_null() => {
            return Err(invalid(
                "deformation plugin without a deformation vtable".into(),
            ));
        }
        // SAFETY: static vtable in a never-unloaded library.
        PluginKind::Deformation => deformation = Some(unsafe { &*decl.deformation }),
        PluginKind::Renderer if decl.renderer.is_null() => {
            return Err(invalid("renderer plugin without a renderer vtable".into()));
        }
        // SAFETY: static vtable in a never-unloaded library.
        PluginKind::Renderer => renderer = Some(unsafe { &*decl.renderer }),
        PluginKind::Actuator if decl.actuator.is_null() => {
            return Err(invalid("actuator plugin without an actuator vtable".into()));
        }
        // SAFETY: static vtable in a never-unloaded library.
        PluginKind::Actuator => actuator = Some(unsafe { &*decl.actuator }),
    }
    // SAFETY: the entry of a checked, never-unloaded library.
    let schema = unsafe { voxflex_abi::params_schema::read(&name, decl.params_schema) }
        .map_err(|e| invalid(format!("its parameter schema could not be read: {e}")))?;
    let params = crate::param_schema::ParamSchema::from_json(&schema)
        .map_err(|e| invalid(format!("declares a {e} the host cannot read")))?;
    tracing::debug!(plugin = %name, %version, path = %path.display(), "plugin loaded");
    Ok(LoadedPlugin {
        path: path.to_path_buf(),
        name,
        version,
        description,
        kind,
        capabilities: decl.capabilities,
        abi_version: header.abi_version,
        deformation,
        renderer,
        actuator,
        params,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_names_follow_the_crate_convention() {
        let f = library_file_name("mass-spring");
        assert!(f.contains("voxflex_mass_spring"), "{f}");
    }

    #[test]
    fn not_found_lists_the_directories() {
        let e = load_by_name("nope", &[PathBuf::from("/definitely/missing")]).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("plugin `nope` not found") && msg.contains("/definitely/missing"),
            "{msg}"
        );
    }

    #[test]
    fn library_files_are_listed_once_in_search_order() {
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        for (d, n) in [(&a, "x"), (&a, "w"), (&b, "x")] {
            std::fs::write(d.path().join(library_file_name(n)), b"").unwrap();
        }
        std::fs::write(a.path().join("libother.so"), b"").unwrap();
        let dirs = [
            a.path().to_path_buf(),
            b.path().to_path_buf(),
            a.path().to_path_buf(),
        ];
        let files = library_files(&dirs);
        assert_eq!(
            files,
            vec![
                a.path().join(library_file_name("w")),
                a.path().join(library_file_name("x")),
                b.path().join(library_file_name("x")),
            ]
        );
    }

    #[test]
    fn non_library_file_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(library_file_name("junk"));
        std::fs::write(&p, b"not an elf").unwrap();
        let e = load_file(&p).unwrap_err().to_string();
        assert!(e.starts_with(&p.display().to_string()), "{e}");
    }
}
