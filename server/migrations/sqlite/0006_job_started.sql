-- When the job's current (or last) attempt was leased, in milliseconds
-- since the epoch: with finished_at, how long a job of its kind takes,
-- which the clients' estimates of the time left are made of.
ALTER TABLE jobs ADD COLUMN started_at INTEGER;
