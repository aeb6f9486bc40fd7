"""TacTip → exoskeleton teleoperation (White 2023): graphs/teleop.yaml, teleop_cnn.yaml, tactip_dataset.yaml.

================== ============= ===================================================
block              module        what
================== ============= ===================================================
tactip_sim         tactip_sim    synthetic TacTip camera frames (pins, contact, noise)
camera             camera        OpenCV cameras, video files or image folders
crop               image         crop frames to a region
adaptive_threshold image         Gaussian adaptive threshold (C −25, radius 15)
blob_detect        image         pin detection per sensor (Table 3.1)
blob_mask          image         mask image from detected pins
ssim               ssim          SSIM against a reference frame (numba, exact)
linear_force       force_linear  SSIM → force by a line per sensor
cnn_force          cnn           CNN contact-force estimator (torch, optional)
fsr_force          exo           FSR reading → force (eq. 3.10)
exo_kinematics     exo           exoskeleton angles → finger joint angles (eq. 3.3–3.8)
fingertip_force    exo           fingertip force (eq. 3.9)
gripper_command    exo           finger pose → gripper command in [0, 1]
force_feedback     feedback      blocking / variable force feedback with clamps and stall fail-safe
grasp_sim          grasp_sim     gripper with soft and firm objects
serial_io          serial_io     the exoskeleton's serial link (real, emulated or in-process sim)
================== ============= ===================================================

Beside the blocks: ``hand`` (finger names), ``exo_protocol`` (the serial line protocol),
``exo_device`` (device model), ``exo_emulator`` (``flowtact sim exo``), and the commands
``fit_force`` (``flowtact fit-force``) and ``train_force`` (``flowtact train-force``).
"""
