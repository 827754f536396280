"""The foundation models as Gymnasium wrappers, each for one env and (``Vector*``) for a vector env.

- ``InstructionGoal``: C-Steve-1's goal embedding of a text instruction in the observation.
- ``CClipReward``: MineCLIP-style dense reward from C-CLIP's video-text similarity.
- ``CVPTFeatures``: the frozen C-VPT's Transformer-XL features as the observation.

Each loads the shipped ``weights/`` export by default; ``zoo.gym.wrappers.base`` has the
batching and the autoreset handling they share.
"""

from zoo.gym.wrappers.cclip_reward import CClipReward, VectorCClipReward
from zoo.gym.wrappers.cvpt_features import CVPTFeatures, VectorCVPTFeatures
from zoo.gym.wrappers.instruction_goal import InstructionGoal, VectorInstructionGoal

__all__ = [
    "CClipReward",
    "CVPTFeatures",
    "InstructionGoal",
    "VectorCClipReward",
    "VectorCVPTFeatures",
    "VectorInstructionGoal",
]
