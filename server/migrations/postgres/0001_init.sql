-- aobake metadata and job queue (DESIGN §8), PostgreSQL: mirrors
-- migrations/sqlite one for one. Times are milliseconds since
-- the Unix epoch, read from the database clock.

CREATE TABLE uploads (
    -- The same file may be uploaded as a character and as clips.
    digest     TEXT NOT NULL,
    kind       TEXT NOT NULL CHECK (kind IN ('character', 'clips')),
    bundle     BOOLEAN NOT NULL,
    bytes      BIGINT NOT NULL,
    summary    TEXT NOT NULL,
    created_at BIGINT NOT NULL,
    PRIMARY KEY (digest, kind)
);

CREATE TABLE bakes (
    id          BIGSERIAL PRIMARY KEY,
    key         TEXT NOT NULL,
    character   TEXT NOT NULL,
    clips       TEXT NOT NULL,
    method      TEXT NOT NULL,
    params      TEXT NOT NULL,
    state       TEXT NOT NULL,
    priority    BIGINT NOT NULL DEFAULT 0,
    total_work  BIGINT NOT NULL,
    done_work   BIGINT NOT NULL DEFAULT 0,
    jobs_total  BIGINT NOT NULL,
    jobs_done   BIGINT NOT NULL DEFAULT 0,
    asset       TEXT,
    report      TEXT,
    plot        TEXT,
    error       TEXT,
    created_at  BIGINT NOT NULL,
    updated_at  BIGINT NOT NULL,
    finished_at BIGINT
);
CREATE INDEX bakes_by_key ON bakes (key, state);
CREATE INDEX bakes_by_character ON bakes (character, method, id);

CREATE TABLE jobs (
    id                BIGSERIAL PRIMARY KEY,
    bake_id           BIGINT NOT NULL REFERENCES bakes (id),
    idx               BIGINT NOT NULL,
    kind              TEXT NOT NULL,
    spec              TEXT NOT NULL,
    work              BIGINT NOT NULL,
    state             TEXT NOT NULL,
    attempts          BIGINT NOT NULL DEFAULT 0,
    max_attempts      BIGINT NOT NULL,
    run_at            BIGINT NOT NULL DEFAULT 0,
    -- Dependencies not yet completed: the job becomes available at 0.
    pending_deps      BIGINT NOT NULL DEFAULT 0,
    worker            TEXT,
    lease_token       TEXT,
    lease_expires_at  BIGINT,
    progress          BIGINT NOT NULL DEFAULT 0,
    checkpoint_step   TEXT,
    checkpoint_cursor BIGINT,
    checkpoint_blob   TEXT,
    outputs           TEXT,
    timings           TEXT,
    error             TEXT,
    finished_at       BIGINT,
    UNIQUE (bake_id, idx)
);
CREATE INDEX jobs_by_state ON jobs (state, run_at);
CREATE INDEX jobs_by_bake ON jobs (bake_id, idx);
-- The claim: the first available job of a bake, in graph order.
CREATE INDEX jobs_ready_in_bake ON jobs (bake_id, state, idx);

CREATE TABLE job_deps (
    job_id BIGINT NOT NULL REFERENCES jobs (id),
    dep_id BIGINT NOT NULL REFERENCES jobs (id),
    -- The dependency's index in the bake's graph, so listing a job's
    -- dependencies needs no join.
    dep_idx BIGINT NOT NULL,
    PRIMARY KEY (job_id, dep_id)
);
CREATE INDEX job_deps_by_dep ON job_deps (dep_id);

CREATE TABLE workers (
    id         TEXT PRIMARY KEY,
    state      TEXT NOT NULL,
    job_id     BIGINT,
    last_seen  BIGINT NOT NULL,
    started_at BIGINT NOT NULL
);

-- Failures of one worker on one bake; past a limit the worker is kept off
-- that bake.
CREATE TABLE worker_failures (
    bake_id  BIGINT NOT NULL,
    worker   TEXT NOT NULL,
    failures BIGINT NOT NULL,
    PRIMARY KEY (bake_id, worker)
);

CREATE TABLE tokens (
    hash       TEXT PRIMARY KEY,
    name       TEXT NOT NULL,
    scopes     TEXT NOT NULL,
    created_at BIGINT NOT NULL
);

CREATE TABLE counters (
    name  TEXT PRIMARY KEY,
    value BIGINT NOT NULL
);
INSERT INTO counters (name, value) VALUES ('lease_expiries', 0);
