//! Trajectories and their HTML player (to come).
