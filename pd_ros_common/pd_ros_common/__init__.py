"""What the powered-descent nodes, bringup tools and tests share (see the README's layout table).

`names` (topic and service names), `qos` (QoS profiles), `convert` (messages <-> numpy),
`params` (typed, checked parameters), `node_help` (`--help` of a node), `run` (a node's
`main`), `process` (child processes and their supervision), `domain` (a ROS domain of one's own),
`session` (a node with its own context and executor, for tools and benches outside the stack),
`clients` (service clients with the QoS a burst needs), `cli` (a tool's own arguments apart from
its `--ros-args`), `diagnostics` (/diagnostics: a node's report, levels, the 1 Hz publisher).
Importing the package imports nothing; each module imports what it needs.
"""
