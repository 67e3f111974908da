//! A bake's inputs as bytes and as imported data: the character upload
//! and the clip uploads, each one content-addressed blob.

use crate::{
    Character, Clip, ImportError, Limits, SideFile, Upload, import_character, import_clips,
};

/// An upload held in memory: the main file (`.glb` or `.gltf`) and the
/// files uploaded beside it.
#[derive(Debug, Clone, Default)]
pub struct UploadBytes {
    /// The `.glb` or `.gltf` bytes.
    pub main: Vec<u8>,
    /// Buffers and images uploaded with a `.gltf`.
    pub side_files: Vec<SideFile>,
}

/// Why an upload blob cannot be read back.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("a bundled upload is malformed: {0}")]
pub struct BundleError(&'static str);

impl UploadBytes {
    /// A self-contained file.
    pub fn single(main: Vec<u8>) -> Self {
        Self {
            main,
            side_files: Vec::new(),
        }
    }

    /// The borrowed form core's import reads.
    pub fn upload(&self) -> Upload<'_> {
        Upload {
            main: &self.main,
            side_files: &self.side_files,
        }
    }

    /// The upload's content digest ([`Upload::digest`]).
    pub fn digest(&self) -> String {
        self.upload().digest()
    }

    /// Leaves out the side files the main file does not refer to, and
    /// names each file kept by the path its URI resolves to, so that a
    /// client that sends a folder's every file, or bare file names (a
    /// browser's `rig.bin` for a URI `data/rig.bin`), gets the digest of
    /// the command line, which sends what the glTF uses under those names;
    /// returns the names left out. A main file that cannot be read keeps
    /// them all: its import says what is wrong.
    pub fn keep_referenced(&mut self, limits: &Limits) -> Vec<String> {
        if self.side_files.is_empty() {
            return Vec::new();
        }
        let Ok(used) = crate::import::referenced_files(&self.main, limits) else {
            return Vec::new();
        };
        // The files the import will use, found as the import finds them.
        let files = crate::import::SideFiles::new(&self.side_files);
        let mut wanted = vec![false; self.side_files.len()];
        // The path of the first URI that names each file.
        let mut named: Vec<Option<&String>> = vec![None; self.side_files.len()];
        for name in &used {
            match files.position(name) {
                Some(i) => {
                    wanted[i] = true;
                    named[i].get_or_insert(name);
                }
                // Not found: keep every file it might have meant, so the
                // import sees the same ambiguity (two `x.bin` for a URI
                // `c/x.bin`) rather than the one left after pruning.
                None => {
                    for &i in files.sharing_last_segment(name) {
                        wanted[i] = true;
                    }
                }
            }
        }
        let (kept, left): (Vec<_>, Vec<_>) = std::mem::take(&mut self.side_files)
            .into_iter()
            .zip(wanted.into_iter().zip(named))
            .partition(|(_, (wanted, _))| *wanted);
        // (A file named by a URI that resolved to it: no other file has
        // that path, or the URI would have found that one.)
        self.side_files = kept
            .into_iter()
            .map(|(f, (_, named))| match named {
                Some(path) => SideFile {
                    name: path.clone(),
                    ..f
                },
                None => f,
            })
            .collect();
        left.into_iter().map(|(f, _)| f.name).collect()
    }

    /// Whether the upload is more than one file.
    pub fn is_bundle(&self) -> bool {
        !self.side_files.is_empty()
    }

    /// The upload as one blob whose sha256 is [`UploadBytes::digest`]: the
    /// file itself when it comes alone, else the byte stream the digest
    /// hashes (the main file, then the side files sorted by name, each
    /// framed by little-endian u64 lengths).
    pub fn to_blob(&self) -> Vec<u8> {
        if !self.is_bundle() {
            return self.main.clone();
        }
        let mut out = Vec::new();
        out.extend((self.main.len() as u64).to_le_bytes());
        out.extend(&self.main);
        let mut files: Vec<&SideFile> = self.side_files.iter().collect();
        files.sort_by(|a, b| a.name.cmp(&b.name));
        for f in files {
            out.extend((f.name.len() as u64).to_le_bytes());
            out.extend(f.name.as_bytes());
            out.extend((f.bytes.len() as u64).to_le_bytes());
            out.extend(&f.bytes);
        }
        out
    }

    /// Reads back what [`UploadBytes::to_blob`] wrote; `bundle` says which
    /// of its two forms the blob has (the store records it).
    pub fn from_blob(blob: &[u8], bundle: bool) -> Result<Self, BundleError> {
        if !bundle {
            return Ok(Self::single(blob.to_vec()));
        }
        fn take<'b>(rest: &mut &'b [u8], what: &'static str) -> Result<&'b [u8], BundleError> {
            let (len, tail) = rest.split_first_chunk::<8>().ok_or(BundleError(what))?;
            let len = usize::try_from(u64::from_le_bytes(*len)).map_err(|_| BundleError(what))?;
            if len > tail.len() {
                return Err(BundleError(what));
            }
            let (bytes, tail) = tail.split_at(len);
            *rest = tail;
            Ok(bytes)
        }
        let mut rest = blob;
        let main = take(&mut rest, "main file")?.to_vec();
        let mut side_files = Vec::new();
        while !rest.is_empty() {
            if side_files.len() == MAX_SIDE_FILES {
                return Err(BundleError(
                    "more side files than an upload may have (1,024)",
                ));
            }
            let name = std::str::from_utf8(take(&mut rest, "side file name")?)
                .map_err(|_| BundleError("a side file name is not UTF-8"))?
                .to_owned();
            let bytes = take(&mut rest, "side file")?.to_vec();
            side_files.push(SideFile { name, bytes });
        }
        if side_files.is_empty() {
            return Err(BundleError("a bundle without side files"));
        }
        Ok(Self { main, side_files })
    }
}

/// Side files one upload may have (a `.gltf`'s buffers and images).
pub const MAX_SIDE_FILES: usize = 1024;

/// Clip uploads one new bake may name: each is read into memory and
/// imported with the character.
pub const MAX_CLIP_FILES: usize = 256;

/// Why a new bake's list of clip uploads is refused. (The message of
/// `Twice` names indices; the command line and the API name the files.)
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ClipListError {
    /// More than [`MAX_CLIP_FILES`] (how many).
    #[error(
        "{0} clip files, over the limit of {MAX_CLIP_FILES}: put animations together in fewer files"
    )]
    TooMany(usize),
    /// The same upload at two places of the list (their indices).
    #[error("clip files {0} and {1} are the same")]
    Twice(usize, usize),
}

/// Checks the clip uploads (their digests) of a new bake: at most
/// [`MAX_CLIP_FILES`], each once (a clip given twice would be baked
/// twice under one name, and its key would differ from the same bake
/// given once). Bakes already accepted are not checked again.
pub fn check_clip_list<S: AsRef<str>>(digests: &[S]) -> Result<(), ClipListError> {
    if digests.len() > MAX_CLIP_FILES {
        return Err(ClipListError::TooMany(digests.len()));
    }
    let mut seen = std::collections::HashMap::with_capacity(digests.len());
    for (i, d) in digests.iter().enumerate() {
        if let Some(&first) = seen.get(d.as_ref()) {
            return Err(ClipListError::Twice(first, i));
        }
        seen.insert(d.as_ref(), i);
    }
    Ok(())
}

/// A bake's inputs, imported: the character, every clip (those of the
/// clip uploads first, in upload order, then the character's own) and the
/// digests that enter the bake key.
#[derive(Debug, Clone)]
pub struct BakeInputs {
    /// The merged occluder and its skeleton.
    pub character: Character,
    /// Every clip.
    pub clips: Vec<Clip>,
    /// sha256 of the character upload.
    pub character_digest: String,
    /// sha256 of each clip upload.
    pub clip_digests: Vec<String>,
    /// What import accepted but flagged, prefixed by the file it is about
    /// (`character` or `clips[i]`).
    pub warnings: Vec<String>,
}

/// Which input failed to import, and why.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {source}")]
pub struct InputError {
    /// `character` or `clips[i]`.
    pub what: String,
    /// The import error.
    #[source]
    pub source: ImportError,
}

/// The one-frame clip a character without animation is baked with: its
/// rest pose (see [`BakeInputs::load`]).
pub const REST_CLIP: &str = "rest";

impl BakeInputs {
    /// Imports the character and binds the clip uploads' animations to its
    /// nodes by name.
    pub fn load(
        character: &UploadBytes,
        clips: &[UploadBytes],
        limits: &Limits,
    ) -> Result<Self, InputError> {
        let imported =
            import_character(character.upload(), limits).map_err(|source| InputError {
                what: "character".into(),
                source,
            })?;
        let mut warnings: Vec<String> = imported
            .warnings
            .iter()
            .map(|w| format!("character: {w}"))
            .collect();
        let mut all = Vec::new();
        let mut clip_digests = Vec::new();
        for (i, upload) in clips.iter().enumerate() {
            let (extra, w) =
                import_clips(upload.upload(), &imported.character, limits).map_err(|source| {
                    InputError {
                        what: format!("clips[{i}]"),
                        source,
                    }
                })?;
            warnings.extend(w.into_iter().map(|w| format!("clips[{i}]: {w}")));
            all.extend(extra);
            clip_digests.push(upload.digest());
        }
        all.extend(imported.clips);
        // A static mesh (no animation at all) is baked in the one pose it
        // has: a clip of that pose, so every stage that reads clip frames
        // (the static average's rows, the evaluation, the previews) reads
        // it, and the methods that fit AO to poses say they need more.
        if all.is_empty() {
            warnings.push(format!(
                "the character has no animation: it is baked as modelled, its rest pose as a one-frame clip {REST_CLIP:?} (static-average bakes its per-vertex AO, texel-linear an AO texture, grid and the cubemaps the AO it casts; vertex-linear and vertex-clustered need clips: pass --clips FILE)"
            ));
            all.push(Clip {
                name: REST_CLIP.into(),
                channels: Vec::new(),
                duration: 0.0,
            });
        }
        // Clips are chosen by name (`--clip`, train and test clips): a
        // repeated name reaches only the first of its clips.
        let mut names = std::collections::HashSet::with_capacity(all.len());
        for clip in &all {
            if !names.insert(clip.name.as_str()) {
                warnings.push(format!(
                    "two clips are named {:?} (the same file given as the character and as --clips?): a clip chosen by that name is the first one",
                    clip.name
                ));
            }
        }
        Ok(Self {
            character: imported.character,
            clips: all,
            character_digest: character.digest(),
            clip_digests,
            warnings,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parts a glTF does not refer to are left out and named; the digest
    /// is then that of the files it uses, hashed as docs/asset-format.md
    /// says.
    #[test]
    fn only_the_files_the_gltf_uses_are_kept() {
        let main = br#"{"asset":{"version":"2.0"},"buffers":[{"uri":"rig.bin","byteLength":4}],"images":[{"uri":"skin%20a.png"}]}"#.to_vec();
        let file = |name: &str, bytes: &[u8]| SideFile {
            name: name.into(),
            bytes: bytes.to_vec(),
        };
        let mut sent = UploadBytes {
            main: main.clone(),
            side_files: vec![
                file("notes.txt", b"x"),
                file("skin a.png", b"png"),
                file("rig.bin", b"1234"),
            ],
        };
        assert_eq!(sent.keep_referenced(&Limits::default()), ["notes.txt"]);
        // Kept as the import finds them: a bare file name for a URI in a
        // folder (what a browser sends), or a name with `./`.
        let mut bare = UploadBytes {
            main: br#"{"asset":{"version":"2.0"},"buffers":[{"uri":"data/rig.bin","byteLength":4},{"uri":"skin.bin","byteLength":1}]}"#.to_vec(),
            side_files: vec![file("rig.bin", b"1234"), file("./skin.bin", b"s"), file("other.bin", b"o")],
        };
        assert_eq!(bare.keep_referenced(&Limits::default()), ["other.bin"]);
        // Named by their URIs' paths: the digest is the command line's,
        // which sends them under those names.
        let names: Vec<&str> = bare.side_files.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["data/rig.bin", "skin.bin"]);
        let as_named = UploadBytes {
            main: bare.main.clone(),
            side_files: vec![file("skin.bin", b"s"), file("data/rig.bin", b"1234")],
        };
        assert_eq!(bare.digest(), as_named.digest());
        // And the import finds them under those names (then finds no mesh).
        let err = crate::import_character(bare.upload(), &Limits::default()).unwrap_err();
        assert_eq!(err.code(), "no_geometry", "{err}");
        // A URI that two files might mean keeps both: the import then says
        // it cannot tell, as it does for what was sent, rather than taking
        // the one left after the other was pruned.
        let mut two = UploadBytes {
            main: br#"{"asset":{"version":"2.0"},"buffers":[{"uri":"a/x.bin","byteLength":1},{"uri":"c/x.bin","byteLength":1}]}"#.to_vec(),
            side_files: vec![file("a/x.bin", b"a"), file("b/x.bin", b"b"), file("y.bin", b"y")],
        };
        assert_eq!(two.keep_referenced(&Limits::default()), ["y.bin"]);
        let err = crate::import_character(two.upload(), &Limits::default()).unwrap_err();
        assert!(
            err.to_string()
                .starts_with("buffers[1].uri: file \"c/x.bin\" is not among"),
            "{err}"
        );
        let used = UploadBytes {
            main: main.clone(),
            side_files: vec![file("rig.bin", b"1234"), file("skin a.png", b"png")],
        };
        assert_eq!(sent.digest(), used.digest());
        // The documented stream: main, then the side files sorted by name,
        // each length a u64 LE.
        let mut stream = Vec::new();
        stream.extend((main.len() as u64).to_le_bytes());
        stream.extend(&main);
        for (name, bytes) in [("rig.bin", &b"1234"[..]), ("skin a.png", b"png")] {
            stream.extend((name.len() as u64).to_le_bytes());
            stream.extend(name.as_bytes());
            stream.extend((bytes.len() as u64).to_le_bytes());
            stream.extend(bytes);
        }
        assert_eq!(used.to_blob(), stream);
        assert_eq!(used.digest(), crate::digest::sha256_hex(&stream));
        // A main file that cannot be read keeps everything: its import
        // says why.
        let mut broken = UploadBytes {
            main: b"{".to_vec(),
            side_files: vec![file("rig.bin", b"1234")],
        };
        assert!(broken.keep_referenced(&Limits::default()).is_empty());
        assert_eq!(broken.side_files.len(), 1);
    }

    /// A new bake names each clip upload once, and at most 256.
    #[test]
    fn a_clip_list_is_checked() {
        assert_eq!(check_clip_list(&["a", "b"]), Ok(()));
        assert_eq!(
            check_clip_list(&["a", "b", "a"]),
            Err(ClipListError::Twice(0, 2))
        );
        let many = vec!["x".to_owned(); MAX_CLIP_FILES + 1];
        assert_eq!(check_clip_list(&many), Err(ClipListError::TooMany(257)));
    }

    /// A bundle of more side files than an upload may have is refused
    /// while it is read, not after each became an allocation.
    #[test]
    fn a_bundle_of_too_many_side_files_is_refused() {
        let bundle = |files: usize| {
            let mut blob = Vec::new();
            blob.extend(2u64.to_le_bytes());
            blob.extend(b"{}");
            for i in 0..files {
                let name = format!("{i}.bin");
                blob.extend((name.len() as u64).to_le_bytes());
                blob.extend(name.as_bytes());
                blob.extend(0u64.to_le_bytes());
            }
            blob
        };
        let read = UploadBytes::from_blob(&bundle(MAX_SIDE_FILES), true).unwrap();
        assert_eq!(read.side_files.len(), MAX_SIDE_FILES);
        let err = UploadBytes::from_blob(&bundle(MAX_SIDE_FILES + 1), true).unwrap_err();
        assert!(err.to_string().contains("more side files"), "{err}");
    }

    /// docs/asset-format.md's table of algorithm versions is the code's.
    #[test]
    fn the_docs_list_the_algorithm_versions() {
        use aobake_runtime::method::{cubemap, grid, vertex};
        let docs = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../docs/asset-format.md"
        ))
        .unwrap();
        for (family, version) in [
            ("vertex", vertex::ALGORITHM_VERSION),
            ("grid", grid::ALGORITHM_VERSION),
            ("cubemap", cubemap::ALGORITHM_VERSION),
        ] {
            let row = docs
                .lines()
                .find(|l| l.starts_with(&format!("| {family} |")))
                .unwrap_or_else(|| panic!("no row for {family}"));
            assert!(
                row.ends_with(&format!("| {version} |")),
                "{family} is at version {version}: {row}"
            );
        }
    }

    #[test]
    fn a_clip_name_given_twice_is_warned_about() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../tests/data/characters/RiggedSimple/RiggedSimple.glb"
        );
        let bytes = std::fs::read(path).unwrap();
        let limits = Limits::default();
        let alone = BakeInputs::load(&UploadBytes::single(bytes.clone()), &[], &limits).unwrap();
        assert!(
            !alone.warnings.iter().any(|w| w.contains("two clips")),
            "{:?}",
            alone.warnings
        );
        let twice = BakeInputs::load(
            &UploadBytes::single(bytes.clone()),
            &[UploadBytes::single(bytes)],
            &limits,
        )
        .unwrap();
        assert_eq!(twice.clips.len(), 2);
        assert!(
            twice
                .warnings
                .iter()
                .any(|w| w.contains("two clips are named \"animation_0\"")),
            "{:?}",
            twice.warnings
        );
    }

    #[test]
    fn a_bundle_blob_hashes_to_the_upload_digest_and_reads_back() {
        let u = UploadBytes {
            main: b"{\"asset\":{}}".to_vec(),
            side_files: vec![
                SideFile {
                    name: "b.bin".into(),
                    bytes: vec![1, 2, 3],
                },
                SideFile {
                    name: "a.png".into(),
                    bytes: vec![],
                },
            ],
        };
        let blob = u.to_blob();
        assert_eq!(crate::digest::sha256_hex(&blob), u.digest());
        let back = UploadBytes::from_blob(&blob, true).unwrap();
        assert_eq!(back.main, u.main);
        let names: Vec<&str> = back.side_files.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["a.png", "b.bin"]);
        assert_eq!(back.digest(), u.digest());
        // Truncated anywhere: an error, never a panic.
        for cut in 0..blob.len() {
            let _ = UploadBytes::from_blob(&blob[..cut], true);
        }
        assert!(UploadBytes::from_blob(&blob[..blob.len() - 1], true).is_err());
        let single = UploadBytes::single(b"glTF".to_vec());
        assert_eq!(single.to_blob(), b"glTF");
        assert_eq!(
            crate::digest::sha256_hex(&single.to_blob()),
            single.digest()
        );
    }
}
