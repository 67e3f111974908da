-- A token may expire (`aobake token create --expires-in 30d`, ms since
-- the epoch; NULL: never), and records when it was last used (updated at
-- most once a minute per server), so an operator sees stale CI secrets.
ALTER TABLE tokens ADD COLUMN expires_at BIGINT;
ALTER TABLE tokens ADD COLUMN last_used_at BIGINT;
