"""scratch-bake: the asset pipeline and baking toolchain for 3D projects in Scratch and TurboWarp."""

__version__ = "0.1.0"
