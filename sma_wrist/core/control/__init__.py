"""The control laws (seed Chapters 5-6), each beside its compiled kernel.

- ``adaptive`` / ``adaptive_kernel``: back-stepping adaptive joint law (Sec. 5.2.2, Eqs. 5.22-5.37).
- ``pid`` / ``pid_kernel``: the Sec. 6.1 PID (Table 6.1).
- ``joint_controller``: what the ``adaptive_controller`` node computes each sample (mode composition).
- ``tem`` / ``tem_kernel``: feedback-linearising TEM temperature law (Sec. 5.2, Eqs. 5.38-5.47) and the
  muscle temperature observer.
- ``trajectory``: desired joint angles q_d(t) with analytic derivatives (Sec. 6.1).
"""
