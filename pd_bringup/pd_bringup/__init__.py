"""pd_bringup: launch, parameters, the demo orchestrator, bag record and replay."""
