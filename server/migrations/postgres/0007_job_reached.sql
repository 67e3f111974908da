-- The furthest progress any attempt of the job reached (work units): a
-- job leased again counts what it had done until it passes it, so a
-- bake's progress only moves forward, and the work done again shows as
-- such (running jobs' reached - progress).
ALTER TABLE jobs ADD COLUMN reached BIGINT NOT NULL DEFAULT 0;
UPDATE jobs SET reached = CASE WHEN state = 'completed' THEN work ELSE progress END;
