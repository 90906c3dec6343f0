"""Demonstrations for the DQN (Sec. 2.3): open-loop OCP episodes (`open_loop`) and episodes and
DAgger labels flown by a closed-loop teacher (`teacher_flown`). The replay memory that holds them
in training is `pd_core.dqn.demo_memory`."""
