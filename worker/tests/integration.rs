//! The worker's integration tests, one binary (see STYLE: link time).

mod integration {
    mod gpu;
    mod preview;
    mod trace;

    /// The bytes of `tests/data/characters/NAME/NAME.glb`.
    fn bundled_bytes(name: &str) -> Vec<u8> {
        let path = format!(
            "{}/../tests/data/characters/{name}/{name}.glb",
            env!("CARGO_MANIFEST_DIR")
        );
        std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
    }

    /// `tests/data/characters/NAME/NAME.glb`, imported.
    fn bundled(name: &str) -> aobake_core::Imported {
        aobake_core::import_character(
            aobake_core::Upload::single(&bundled_bytes(name)),
            &aobake_core::Limits::default(),
        )
        .unwrap()
    }
}
