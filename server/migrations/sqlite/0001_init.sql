-- aobake metadata and job queue (DESIGN §8). Times are milliseconds since
-- the Unix epoch, read from the database clock.

CREATE TABLE uploads (
    -- The same file may be uploaded as a character and as clips.
    digest     TEXT NOT NULL,
    kind       TEXT NOT NULL CHECK (kind IN ('character', 'clips')),
    bundle     INTEGER NOT NULL,
    bytes      INTEGER NOT NULL,
    summary    TEXT NOT NULL,
    created_at INTEGER NOT NULL,
    PRIMARY KEY (digest, kind)
);

CREATE TABLE bakes (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    key         TEXT NOT NULL,
    character   TEXT NOT NULL,
    clips       TEXT NOT NULL,
    method      TEXT NOT NULL,
    params      TEXT NOT NULL,
    state       TEXT NOT NULL,
    priority    INTEGER NOT NULL DEFAULT 0,
    total_work  INTEGER NOT NULL,
    done_work   INTEGER NOT NULL DEFAULT 0,
    jobs_total  INTEGER NOT NULL,
    jobs_done   INTEGER NOT NULL DEFAULT 0,
    asset       TEXT,
    report      TEXT,
    plot        TEXT,
    error       TEXT,
    created_at  INTEGER NOT NULL,
    updated_at  INTEGER NOT NULL,
    finished_at INTEGER
);
CREATE INDEX bakes_by_key ON bakes (key, state);
CREATE INDEX bakes_by_character ON bakes (character, method, id);

CREATE TABLE jobs (
    id                INTEGER PRIMARY KEY AUTOINCREMENT,
    bake_id           INTEGER NOT NULL REFERENCES bakes (id),
    idx               INTEGER NOT NULL,
    kind              TEXT NOT NULL,
    spec              TEXT NOT NULL,
    work              INTEGER NOT NULL,
    state             TEXT NOT NULL,
    attempts          INTEGER NOT NULL DEFAULT 0,
    max_attempts      INTEGER NOT NULL,
    run_at            INTEGER NOT NULL DEFAULT 0,
    -- Dependencies not yet completed: the job becomes available at 0.
    pending_deps      INTEGER NOT NULL DEFAULT 0,
    worker            TEXT,
    lease_token       TEXT,
    lease_expires_at  INTEGER,
    progress          INTEGER NOT NULL DEFAULT 0,
    checkpoint_step   TEXT,
    checkpoint_cursor INTEGER,
    checkpoint_blob   TEXT,
    outputs           TEXT,
    timings           TEXT,
    error             TEXT,
    finished_at       INTEGER,
    UNIQUE (bake_id, idx)
);
CREATE INDEX jobs_by_state ON jobs (state, run_at);
CREATE INDEX jobs_by_bake ON jobs (bake_id, idx);
-- The claim: the first available job of a bake, in graph order.
CREATE INDEX jobs_ready_in_bake ON jobs (bake_id, state, idx);

CREATE TABLE job_deps (
    job_id INTEGER NOT NULL REFERENCES jobs (id),
    dep_id INTEGER NOT NULL REFERENCES jobs (id),
    -- The dependency's index in the bake's graph, so listing a job's
    -- dependencies needs no join.
    dep_idx INTEGER NOT NULL,
    PRIMARY KEY (job_id, dep_id)
);
CREATE INDEX job_deps_by_dep ON job_deps (dep_id);

CREATE TABLE workers (
    id         TEXT PRIMARY KEY,
    state      TEXT NOT NULL,
    job_id     INTEGER,
    last_seen  INTEGER NOT NULL,
    started_at INTEGER NOT NULL
);

-- Failures of one worker on one bake; past a limit the worker is kept off
-- that bake.
CREATE TABLE worker_failures (
    bake_id  INTEGER NOT NULL,
    worker   TEXT NOT NULL,
    failures INTEGER NOT NULL,
    PRIMARY KEY (bake_id, worker)
);

CREATE TABLE tokens (
    hash       TEXT PRIMARY KEY,
    name       TEXT NOT NULL,
    scopes     TEXT NOT NULL,
    created_at INTEGER NOT NULL
);

CREATE TABLE counters (
    name  TEXT PRIMARY KEY,
    value INTEGER NOT NULL
);
INSERT INTO counters (name, value) VALUES ('lease_expiries', 0);
