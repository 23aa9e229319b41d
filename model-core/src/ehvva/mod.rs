//! Electro-hydraulic camless valve actuator (Li et al. 2018). (being written)
