-- The lease request that leased a running job (a worker's nonce, the same
-- on each retry of one request until an answer arrives): the same request
-- sent again, after its answer was lost, gets the same job back.
ALTER TABLE jobs ADD COLUMN lease_request TEXT;
