"""Physics and simulation: the plant description (YAML files and their schema), the
excitation signals and the sampled simulator of the linear PMSM axis.
"""

from .excitation import ExcitationSource, make_excitation
from .motor import MotorSimulator, MotorState, simulate, simulate_blocks
from .plant import (
    Plant,
    dump_plant,
    load_plant,
    nominal_plant,
    packaged_plant_path,
    plant_from_dict,
    plant_to_dict,
)

__all__ = [
    "ExcitationSource", "MotorSimulator", "MotorState", "Plant", "dump_plant", "load_plant",
    "make_excitation", "nominal_plant", "packaged_plant_path", "plant_from_dict",
    "plant_to_dict", "simulate", "simulate_blocks"
]
