-- What casts a worker's rays, as it says when it asks for a job: `cpu`,
-- or `gpu: ` and the adapter (`aobake worker --gpu`).
ALTER TABLE workers ADD COLUMN tracer TEXT NOT NULL DEFAULT 'cpu';
