//! A bake as jobs: cutting it into batches or interrupting its jobs never
//! changes a byte of the result, checkpoints resume where they stopped,
//! and the planner's graph is well formed.

use std::collections::HashMap;

use aobake_core::{
    bake::JobEvent,
    bake::vertex::Report,
    bake::{
        Bake, BakeError, BakeParams, Checkpoint, GraphOptions, JobError, JobOutput, JobSink,
        JobSpec, NoSink, PoseSet, Stop, bake_in_process, run_graph,
    },
    method::{Method, vertex::FitStep},
};
use serde_json::json;

use crate::util;

fn quick(method: Method) -> BakeParams {
    let mut p = BakeParams::new(method);
    p.poses = 12;
    p.samples = 32;
    p.eval_poses = 2;
    p.eval_fps = 5.0;
    p
}

/// Saves every checkpoint and asks the job to stop after `stop_after` of
/// them (never when `None`).
#[derive(Default)]
pub(crate) struct Interrupting {
    pub(crate) saved: Vec<Checkpoint>,
    pub(crate) stop_after: Option<usize>,
    pub(crate) progress: Vec<(u64, u64)>,
    /// Checkpoint parts by digest, and the bytes of each saved.
    pub(crate) parts: HashMap<String, Vec<u8>>,
    pub(crate) part_sizes: Vec<usize>,
}

impl JobSink for Interrupting {
    fn checkpoint(&mut self, checkpoint: Checkpoint) -> Result<(), Stop> {
        self.saved.push(checkpoint);
        if Some(self.saved.len()) == self.stop_after {
            return Err(Stop("test".into()));
        }
        Ok(())
    }

    fn progress(&mut self, done: u64, total: u64) {
        self.progress.push((done, total));
    }

    fn save_part(&mut self, bytes: &[u8]) -> Option<String> {
        let digest = aobake_core::bake::sha256_hex(bytes);
        self.part_sizes.push(bytes.len());
        self.parts.insert(digest.clone(), bytes.to_vec());
        Some(digest)
    }

    fn load_part(&mut self, digest: &str) -> Result<Vec<u8>, JobError> {
        self.parts
            .get(digest)
            .cloned()
            .ok_or_else(|| JobError::Failed(format!("no part {digest}")))
    }
}

#[test]
fn a_sample_job_resumes_from_its_checkpoint_with_the_same_bytes() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let inputs = util::inputs(&imported.character, &imported.clips);
    let bake = Bake::new(&inputs, quick(Method::VertexLinear)).unwrap();
    let spec = JobSpec::Sample {
        set: PoseSet::Reference,
        first: 4,
        count: 5,
    };
    let whole = bake.run_job(&spec, &[], None, &mut NoSink).unwrap();
    for stop_after in 1..=4 {
        let mut sink = Interrupting {
            saved: Vec::new(),
            stop_after: Some(stop_after),
            progress: Vec::new(),
            ..Default::default()
        };
        let err = bake.run_job(&spec, &[], None, &mut sink).unwrap_err();
        assert!(matches!(err, JobError::Stopped(_)), "{err}");
        assert!(err.retryable());
        let last = sink.saved.pop().unwrap();
        assert_eq!(last.step, "sample");
        assert_eq!(
            last.cursor, stop_after as u64,
            "a checkpoint after every pose"
        );
        // The next attempt starts at the cursor: it reports that progress
        // first and traces only the poses left.
        let mut next = Interrupting {
            saved: Vec::new(),
            stop_after: None,
            progress: Vec::new(),
            ..Default::default()
        };
        let resumed = bake.run_job(&spec, &[], Some(last), &mut next).unwrap();
        assert_eq!(next.progress[0], (stop_after as u64, 5));
        assert_eq!(next.saved.len(), 4 - stop_after);
        assert_eq!(resumed.outputs, whole.outputs, "stopped after {stop_after}");
    }
    // A checkpoint of another job is refused, not silently mixed in.
    let other = JobSpec::Sample {
        set: PoseSet::Reference,
        first: 0,
        count: 5,
    };
    let mut sink = Interrupting {
        saved: Vec::new(),
        stop_after: Some(2),
        progress: Vec::new(),
        ..Default::default()
    };
    bake.run_job(&spec, &[], None, &mut sink).unwrap_err();
    let foreign = sink.saved.pop().unwrap();
    let err = bake
        .run_job(&other, &[], Some(foreign), &mut NoSink)
        .unwrap_err();
    assert!(
        matches!(err, JobError::Invalid(_)) && !err.retryable(),
        "{err}"
    );
}

#[test]
fn cutting_the_bake_into_other_batches_changes_no_byte() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let inputs = util::inputs(&imported.character, &imported.clips);
    for method in [Method::VertexLinear, Method::VertexClustered] {
        let bake = Bake::new(&inputs, quick(method)).unwrap();
        let reference = bake_in_process(&bake, None).unwrap();
        for batch in [1, 5, 100] {
            let graph = bake.graph(GraphOptions {
                sample_batch: batch,
                sample_rays: 0,
                previews: false,
                ..GraphOptions::default()
            });
            let out = run_graph(&bake, &graph, &HashMap::new(), None, &mut |_, _, _| {}).unwrap();
            let asset = out.last().unwrap().get("asset").unwrap();
            assert_eq!(asset, reference.asset.as_slice(), "{method} batch {batch}");
            let report: Report =
                serde_json::from_slice(out.last().unwrap().get("report.json").unwrap()).unwrap();
            let reference = reference.report.vertex().unwrap();
            assert_eq!(report.evaluation, reference.evaluation);
            assert_eq!(report.ground_truth_noise, reference.ground_truth_noise);
        }
    }
}

#[test]
fn the_graph_lists_dependencies_first_and_covers_every_pose() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let inputs = util::inputs(&imported.character, &imported.clips);
    let bake = Bake::new(&inputs, quick(Method::VertexLinear)).unwrap();
    let graph = bake.graph(GraphOptions {
        sample_batch: 5,
        sample_rays: 0,
        previews: true,
        ..GraphOptions::default()
    });
    for (i, job) in graph.jobs.iter().enumerate() {
        assert!(job.deps.iter().all(|&d| d < i), "{i}: {:?}", job.deps);
    }
    // Workers take the first ready job: the fit comes right after the
    // reference poses it needs; the previews' truth needs nothing and the
    // preview needs it.
    let kinds: Vec<&str> = graph.jobs.iter().map(|j| j.spec.kind()).collect();
    let fit = kinds.iter().position(|&k| k == "fit").unwrap();
    assert!(graph.jobs[..fit].iter().all(|j| matches!(
        j.spec,
        JobSpec::Sample {
            set: PoseSet::Reference,
            ..
        }
    )));
    assert_eq!(
        &kinds[kinds.len() - 3..],
        ["evaluate", "assemble", "preview"]
    );
    let truth: Vec<usize> = (0..kinds.len())
        .filter(|&i| kinds[i] == "preview-truth")
        .collect();
    assert!(!truth.is_empty());
    assert!(truth.iter().all(|&t| graph.jobs[t].deps.is_empty()
        && graph.jobs.last().unwrap().deps.contains(&t)));
    let frames = bake.preview_frames().unwrap().len();
    for set in [PoseSet::Reference, PoseSet::HeldOut, PoseSet::Noise] {
        let covered: usize = graph
            .jobs
            .iter()
            .filter_map(|j| match j.spec {
                JobSpec::Sample { set: s, count, .. } if s == set => Some(count),
                _ => None,
            })
            .sum();
        assert_eq!(covered, bake.poses_in(set), "{set:?}");
    }
    assert_eq!(bake.poses_in(PoseSet::Reference), 12);
    // A batch's poses are built alone, equal to the whole set's slice
    // (across the mixed set's boundary between random poses and clip
    // frames, at 6).
    let all = bake.plan.reference_poses();
    for range in [0..5, 4..9, 6..12, 11..12] {
        assert_eq!(bake.poses(PoseSet::Reference, range.clone()), all[range]);
    }
    let tests: Vec<_> = bake.plan.test_poses().into_iter().map(|t| t.pose).collect();
    assert_eq!(tests.len(), bake.plan.test_count());
    for range in [0..1, 1..4, 2..tests.len()] {
        assert_eq!(bake.poses(PoseSet::HeldOut, range.clone()), tests[range]);
    }
    // One clip: no unseen-clips folds. The fit is worth its steps, the
    // previews' truth its frames; the evaluate, assemble and preview jobs
    // one each.
    assert!(bake.plan.fold_clips().is_empty());
    assert_eq!(
        graph.total_work(),
        (bake.poses_in(PoseSet::Reference)
            + bake.poses_in(PoseSet::HeldOut)
            + bake.poses_in(PoseSet::Noise)
            + FitStep::ALL.len()
            + frames
            + 3) as u64
    );
    // Specs travel through the queue as JSON.
    for job in &graph.jobs {
        let text = serde_json::to_string(&job.spec).unwrap();
        assert_eq!(serde_json::from_str::<JobSpec>(&text).unwrap(), job.spec);
    }
    assert_eq!(
        serde_json::to_value(&graph.jobs[0].spec).unwrap(),
        json!({"kind": "sample", "set": "reference", "first": 0, "count": 5})
    );
}

#[test]
fn a_job_given_the_wrong_inputs_fails_with_a_named_permanent_error() {
    let imported = util::load(&util::character_path("RiggedFigure.glb").unwrap());
    let inputs = util::inputs(&imported.character, &imported.clips);
    let bake = Bake::new(&inputs, quick(Method::VertexLinear)).unwrap();
    let half = bake
        .run_job(
            &JobSpec::Sample {
                set: PoseSet::Reference,
                first: 0,
                count: 6,
            },
            &[],
            None,
            &mut NoSink,
        )
        .unwrap();
    let err = bake
        .run_job(&JobSpec::Fit, &[&half], None, &mut NoSink)
        .unwrap_err();
    assert!(!err.retryable());
    assert!(err.to_string().contains("hold 6 poses, not 12"), "{err}");
    let err = bake
        .run_job(
            &JobSpec::Evaluate,
            &[&JobOutput::default()],
            None,
            &mut NoSink,
        )
        .unwrap_err();
    assert!(
        err.to_string().contains("no dependency produced model"),
        "{err}"
    );
    let err = bake
        .run_job(
            &JobSpec::Sample {
                set: PoseSet::Noise,
                first: 0,
                count: 99,
            },
            &[],
            None,
            &mut NoSink,
        )
        .unwrap_err();
    assert!(err.to_string().contains("outside the set"), "{err}");
}

#[test]
fn parameters_come_from_one_schema_with_named_errors() {
    let defaults = BakeParams::new(Method::VertexClustered);
    let none = serde_json::Map::new();
    assert_eq!(
        BakeParams::with_overrides(Method::VertexClustered, &none).unwrap(),
        defaults
    );
    let o = |v: serde_json::Value| v.as_object().unwrap().clone();
    let p = BakeParams::with_overrides(
        Method::VertexClustered,
        &o(json!({"poses": 64, "clustered.alpha": 5.0, "clustered": {"dimensions": 4}})),
    )
    .unwrap();
    assert_eq!(
        (p.poses, p.clustered.alpha, p.clustered.dimensions),
        (64, 5.0, 4)
    );
    assert_eq!(p.samples, defaults.samples);
    let err = |v| {
        BakeParams::with_overrides(Method::VertexLinear, &o(v))
            .unwrap_err()
            .to_string()
    };
    assert!(err(json!({"posez": 1})).contains("unknown parameter \"posez\""));
    assert!(err(json!({"linear.ridg": 1})).contains("unknown parameter \"linear.ridg\""));
    // The nearest names, and where to see them all.
    let typo = err(json!({"linear.ridg": 1}));
    assert!(typo.contains("did you mean \"linear.ridge\"?"), "{typo}");
    assert!(typo.contains("`aobake params --method "), "{typo}");
    let rays = err(json!({"rays": 64}));
    assert!(rays.contains("did you mean \"samples\"?"), "{rays}");
    assert!(err(json!({"poses": "many"})).contains("invalid type"));
    assert!(err(json!({"poses": 0})).contains("poses must be between 1 and 100000"));
    assert!(err(json!({"method": "vertex-clustered"})).contains("differs"));
    assert!(matches!(
        BakeParams::with_overrides(Method::VertexLinear, &o(json!({"samples": 0}))),
        Err(BakeError::Param(_))
    ));
    // The work bound the service checks grows with every factor.
    let w = defaults.work(1000, 10, 0);
    assert_eq!(
        w,
        (2048 + 32 + 10 + 8) as u128 * 1000 * 256,
        "reference, random held-out, clip frames and the noise re-trace"
    );
}

#[test]
fn unseen_clip_folds_are_jobs_of_their_own_and_threads_change_no_byte() {
    let imported = util::load(&util::character_path("InterpolationTest.glb").unwrap());
    let inputs = util::inputs(&imported.character, &imported.clips);
    for method in [Method::VertexLinear, Method::VertexClustered] {
        let mut params = quick(method);
        params.poses = 48;
        params.samples = 16;
        let bake = Bake::new(&inputs, params).unwrap();
        let folds = bake.plan.fold_clips().len();
        assert!(folds >= 2, "{folds} folds");
        let graph = bake.graph(GraphOptions {
            previews: false,
            ..GraphOptions::default()
        });
        let index = |spec: &JobSpec| graph.jobs.iter().position(|j| j.spec == *spec).unwrap();
        let evaluate = &graph.jobs[index(&JobSpec::Evaluate)];
        for fold in 0..folds {
            let i = index(&JobSpec::Unseen { fold });
            // A fold needs traced poses only (not the fit), so workers run
            // it beside the fit; evaluate gathers every fold.
            assert!(
                graph.jobs[i]
                    .deps
                    .iter()
                    .all(|&d| matches!(graph.jobs[d].spec, JobSpec::Sample { .. })),
                "{method} fold {fold}"
            );
            assert!(evaluate.deps.contains(&i));
        }
        assert!(
            !graph
                .jobs
                .iter()
                .any(|j| j.spec == JobSpec::Unseen { fold: folds })
        );

        // The same bytes and the same evaluation on 1 and on 3 threads.
        let mut events: Vec<(String, u64, u64)> = Vec::new();
        let run = |threads: usize, events: &mut Vec<(String, u64, u64)>| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    run_graph(&bake, &graph, &HashMap::new(), None, &mut |_, job, e| {
                        if let JobEvent::Progress { done, total } = e
                            && matches!(job.spec, JobSpec::Fit | JobSpec::Unseen { .. })
                        {
                            events.push((job.spec.to_string(), done, total));
                        }
                    })
                    .unwrap()
                })
        };
        let one = run(1, &mut events);
        let three = run(3, &mut Vec::new());
        let asset = |out: &[JobOutput]| out.last().unwrap().get("asset").unwrap().to_vec();
        assert!(asset(&one) == asset(&three), "{method}: the assets differ");
        let report = |out: &[JobOutput]| -> Report {
            serde_json::from_slice(out.last().unwrap().get("report.json").unwrap()).unwrap()
        };
        let (a, b) = (report(&one), report(&three));
        assert_eq!(a.evaluation, b.evaluation, "{method}");
        assert_eq!(a.fit, b.fit, "{method}");
        let unseen = a.evaluation.unseen_clips.as_ref().unwrap();
        assert_eq!(unseen.folds.len(), folds);
        assert!(a.timings.unseen_s > 0.0);
        // Every fit job's progress counts its steps in order: 0, 1, …, 4
        // of 4, for the fit and for each fold.
        let steps = FitStep::ALL.len() as u64;
        for name in
            std::iter::once("fit".to_owned()).chain((0..folds).map(|f| format!("unseen fold {f}")))
        {
            let seen: Vec<(u64, u64)> = events
                .iter()
                .filter(|(n, ..)| *n == name)
                .map(|&(_, d, t)| (d, t))
                .collect();
            let want: Vec<(u64, u64)> = (0..=steps).map(|d| (d, steps)).collect();
            assert_eq!(seen, want, "{method} {name}");
        }
    }
}
