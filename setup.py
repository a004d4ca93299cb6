"""CAT: collision-free humanoid traversal in cluttered indoor scenes (HumanoidPF + hybrid scenes)."""

from setuptools import find_packages, setup

setup(
    name="cat-humanoid",
    version="0.1.0",
    description="Collision-free humanoid traversal with HumanoidPF (PyTorch / MuJoCo / Warp re-implementation)",
    python_requires=">=3.10",
    packages=find_packages(include=["cat", "cat.*"]),
    include_package_data=True,
    install_requires=[
        # torch is installed first (CPU build) by the user or .ci/run; a range keeps pip from swapping it.
        "torch>=2.4",
        "numpy>=1.26",
        "scipy>=1.11",
        "rsl-rl-lib==5.5.1",
        "tensordict>=0.10",
        "mujoco==4.0.0",
        "mujoco-warp==4.0.0",
        "warp-lang==1.19.0",
        "mujoco-menagerie>=2026.10.4",
        "trimesh>=4.0",
        "rtree>=1.2",
        "charset-normalizer>=3.0",  # trimesh decodes ASCII STL with it; without it junk files fail obscurely
        "coacd>=1.0.5",
        "pytorch-kinematics>=0.7",
        "rerun-sdk==0.41.0",
        "hydra-core>=1.3",
        # hydra/launcher=joblib (parallel processes) and submitit_local / submitit_slurm (docs/experiments.md)
        "hydra-joblib-launcher>=1.2",
        "hydra-submitit-launcher>=1.2",
        "omegaconf>=2.3",
        "scikit-image>=0.22",
        "pyyaml>=6.0",
        "tqdm>=4.66",
        "matplotlib>=3.8",
        "viser>=1.0",  # click demo web view (scene.on_click / on_pointer_event)
        "fast-simplification>=0.1",  # trimesh's quadric decimation of the G1's visual meshes for the viewer
        "onnx>=1.16",  # scripts/export.py: one self-contained policy file with metadata
        "onnxruntime>=1.18",  # running an exported policy (click demo checkpoint=x.onnx), export parity check
    ],
    extras_require={
        "dev": [
            "pytest>=8",
            "pytest-benchmark>=4",
            "ruff>=0.6",
            "scikit-fmm>=2024.5",
            "embreex>=2.17; platform_machine=='x86_64'",
            # browser test of the click demo: drives the system's Chromium (Debian: apt-get install chromium)
            "playwright>=1.40",
            "pytest-playwright>=0.5",
        ],
    },
)
