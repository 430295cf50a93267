//! PNG plots of trajectories and errors.
