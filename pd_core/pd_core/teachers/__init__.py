"""Guidance laws that teach the network and back it up: ZEM/ZEV (`zemzev`, numpy only: the
runtime layer's fallback), the receding-horizon optimal-control teacher (`mpc`), and the registry
of controllers by name (`registry`). This package imports nothing itself, so the runtime can load
`zemzev` without the optimal-control stack."""
