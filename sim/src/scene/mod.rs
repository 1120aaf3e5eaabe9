//! Scenes: a mesh, its materials, what is held, the targets behind the tissue, the planned
//! viewpoint and the solver settings. Built-in scenes are TOML files compiled into the crate
//! (`sim/scenes/`), which double as documented examples of the format.

mod build;
mod spec;

pub use build::{BuildOptions, HeldError, Scene, TIME_STEP_RANGE_S};
pub use spec::{
    ForceModelSpec, HeldSelection, IncisionDirections, IncisionError, InclusionSpec, LayerSpec,
    MaskFile, MeshSource, RegionMaterial, SceneSpec, Target, Viewpoint,
};

use std::path::{Path, PathBuf};

use crate::ReadError;

/// Built-in scenes: name and TOML text.
pub const BUILTIN: [(&str, &str); 8] = [
    ("chest-wall", include_str!("../../scenes/chest-wall.toml")),
    (
        "chest-wall-fem",
        include_str!("../../scenes/chest-wall-fem.toml"),
    ),
    ("sheet", include_str!("../../scenes/sheet.toml")),
    ("bar", include_str!("../../scenes/bar.toml")),
    ("body-wall", include_str!("../../scenes/body-wall.toml")),
    ("skin-block", include_str!("../../scenes/skin-block.toml")),
    ("thorax", include_str!("../../scenes/thorax.toml")),
    ("gauze", include_str!("../../scenes/gauze.toml")),
];

/// Why a scene could not be loaded or built.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// Neither a built-in scene's name nor an existing file.
    #[error(
        "unknown scene {name:?}: not a built-in scene ({}) nor an existing file",
        builtin_names()
    )]
    Unknown {
        /// The name given.
        name: String,
    },
    /// The scene file is not valid TOML or JSON for a [`SceneSpec`].
    #[error("{path}: {error}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What the parser said.
        error: SpecSyntaxError,
    },
    /// The spec parsed but says something impossible (a bad size, a duplicate region).
    #[error("scene {scene:?}: {message}")]
    Invalid {
        /// The scene's name.
        scene: String,
        /// What is wrong.
        message: String,
    },
    /// The `[solver]` settings are out of range.
    #[error("scene {scene:?}: {error}")]
    Solver {
        /// The scene's name.
        scene: String,
        /// The setting out of range.
        error: crate::solver::SettingsError,
    },
    /// The incision directions are unusable.
    #[error("scene {scene:?}: {error}")]
    Incision {
        /// The scene's name.
        scene: String,
        /// What is wrong with them.
        error: IncisionError,
    },
    /// A `[[held]]` selection is unusable.
    #[error("scene {scene:?}: {error}")]
    Held {
        /// The scene's name.
        scene: String,
        /// What is wrong with it.
        error: HeldError,
    },
    /// The mesh file (or a segmentation file) could not be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The model could not be built from the mesh and the materials.
    #[error("scene {scene:?}: {source}")]
    Model {
        /// The scene's name.
        scene: String,
        /// Why not.
        source: crate::model::ModelError,
    },
    /// The segmentation could not be meshed.
    #[error("scene {scene:?}: {source}")]
    Segmentation {
        /// The scene's name.
        scene: String,
        /// Why not.
        source: crate::SegmentationError,
    },
    /// The generated mesh is invalid.
    #[error("scene {scene:?}: {source}")]
    Mesh {
        /// The scene's name.
        scene: String,
        /// What is wrong with it.
        source: crate::MeshError,
    },
}

/// A scene file that is not valid TOML (or JSON) for a [`SceneSpec`].
#[derive(Debug, thiserror::Error)]
pub enum SpecSyntaxError {
    /// The TOML parser's error.
    #[error(transparent)]
    Toml(#[from] toml::de::Error),
    /// The JSON parser's error.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
}

fn builtin_names() -> String {
    BUILTIN.map(|(n, _)| n).join(", ")
}

/// Parses a scene from TOML (or JSON when `path` ends in `.json`); `path` names the source in
/// errors.
pub fn parse_spec(text: &str, path: &Path) -> Result<SceneSpec, SceneError> {
    let parsed = if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        serde_json::from_str(text).map_err(SpecSyntaxError::from)
    } else {
        toml::from_str(text).map_err(SpecSyntaxError::from)
    };
    parsed.map_err(|error| SceneError::Parse {
        path: path.to_path_buf(),
        error,
    })
}

/// The spec of a built-in scene.
pub fn builtin_spec(name: &str) -> Option<SceneSpec> {
    let (n, text) = BUILTIN.iter().find(|(n, _)| *n == name)?;
    // The built-in files are tested to parse; a failure here is a bug in the crate.
    parse_spec(text, Path::new(&format!("<built-in {n}>"))).ok()
}

/// Where a scene spec came from, for resolving relative paths.
#[derive(Debug, Clone, PartialEq)]
pub enum SpecOrigin {
    /// One of the built-in scenes (`sim/scenes/*.toml`): paths are relative to `sim/scenes/`.
    BuiltIn,
    /// A scene file (its path): paths in it are relative to its directory.
    File(PathBuf),
}

/// Finds a scene by built-in name or scene-file path (`.toml` / `.json`).
pub fn find_spec(name_or_path: &str) -> Result<(SceneSpec, SpecOrigin), SceneError> {
    if let Some(spec) = builtin_spec(name_or_path) {
        return Ok((spec, SpecOrigin::BuiltIn));
    }
    let path = Path::new(name_or_path);
    if !path.exists() {
        return Err(SceneError::Unknown {
            name: name_or_path.to_owned(),
        });
    }
    if crate::io::is_mesh_file(path) {
        // A bare mesh file: the default material on every region, nothing held.
        let spec = SceneSpec {
            name: path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            description: format!("mesh file {}", path.display()),
            gravity_m_per_s2: [0.0; 3],
            mesh: MeshSource::File {
                path: path.file_name().map(Into::into).unwrap_or_default(),
                unit_m: 1.0,
            },
            materials: Vec::new(),
            held: Vec::new(),
            targets: Vec::new(),
            viewpoint: None,
            incision: Default::default(),
            cut_threshold_newtons: 1.0,
            cut_depth_mm: 4.0,
            blade_length_mm: 20.0,
            solver: Default::default(),
            force_model: Default::default(),
        };
        return Ok((spec, SpecOrigin::File(path.to_path_buf())));
    }
    let text = std::fs::read_to_string(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        error: source,
    })?;
    Ok((
        parse_spec(&text, path)?,
        SpecOrigin::File(path.to_path_buf()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_scenes_parse() {
        for (name, _) in BUILTIN {
            let spec = builtin_spec(name).expect(name);
            assert_eq!(spec.name, name);
        }
    }

    #[test]
    fn unknown_fields_and_bad_values_are_errors() {
        let bad = BUILTIN[0]
            .1
            .replace("pretension = 0.04", "pretension = 0.04\ncolour = 3");
        let err = parse_spec(&bad, Path::new("x.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("x.toml") && err.contains("colour"), "{err}");
        assert!(matches!(
            find_spec("no-such-scene"),
            Err(SceneError::Unknown { .. })
        ));
    }

    #[test]
    fn incision_directions_and_cut_threshold_are_checked_when_a_scene_is_built() {
        let spec = |extra: &str| {
            let text = BUILTIN[0]
                .1
                .replacen("[mesh]", &format!("{extra}\n[mesh]"), 1);
            parse_spec(&text, Path::new("x.toml")).expect("parses")
        };
        let build = |extra: &str| {
            Scene::build(
                spec(extra),
                &SpecOrigin::BuiltIn,
                BuildOptions {
                    min_tets: Some(200),
                },
            )
            .map(|s| s.spec)
        };
        assert_eq!(build("").expect("valid").cut_depth_mm, 4.0, "the default");
        let ok = build("cut_threshold_newtons = 0.1\ncut_depth_mm = 4.5\n[incision]\nup = [0.0, 2.0, 0.0]\nalong = [0.0, 1.0, 3.0]").expect("valid");
        let (up, along) = ok.incision.unit().expect("unit");
        assert!(
            (up - crate::Vector3::y()).norm() < 1e-15
                && (along - crate::Vector3::z()).norm() < 1e-15,
            "{up:?} {along:?}"
        );
        assert_eq!((ok.cut_threshold_newtons, ok.cut_depth_mm), (0.1, 4.5));
        for bad in [
            "[incision]\nup = [0.0, 0.0, 1.0]\nalong = [0.0, 0.0, -2.0]",
            "[incision]\nup = [0.0, 0.0, 0.0]\nalong = [1.0, 0.0, 0.0]",
            "[incision]\nup = [0.0, 0.0, 1.0]\nalong = [1e308, 1e308, 0.0]",
            "cut_threshold_newtons = -1.0",
            "cut_threshold_newtons = 0.0",
            "cut_depth_mm = 0.0",
            "cut_depth_mm = -3.0",
            "blade_length_mm = 0.0",
        ] {
            let err = build(bad).expect_err(bad).to_string();
            assert!(
                err.contains("incision")
                    || err.contains("cut_threshold_newtons")
                    || err.contains("cut_depth_mm")
                    || err.contains("blade_length_mm"),
                "{bad}: {err}"
            );
        }
    }
}
