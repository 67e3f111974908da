-- Tokens revoked (`DELETE /v1/tokens/{id}`), by hash: a revoked secret
-- is never valid again, not even when a server starts with it as its
-- admin token (`AOBAKE_ADMIN_TOKEN`), so a leaked secret that was
-- revoked stays revoked across restarts.
CREATE TABLE revoked_tokens (
    hash       TEXT PRIMARY KEY,
    revoked_at BIGINT NOT NULL
);
