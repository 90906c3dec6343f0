"""Demonstrations for the DQN (Sec. 2.3): open-loop OCP episodes (`open_loop`), episodes flown by
a closed-loop teacher (`teacher_flown`) and the teacher's labels on the states a student flies
(`dagger`). The replay memory that holds them in training is `pd_core.dqn.demo_memory`."""
