"""rosbags' RIHS01 hashes, for coolc's interoperability test (tests/ros_rosbags.rs).

Reads a JSON request on stdin: {"register": {type name: .msg text}, "hash": [type
names]}. Registers the given types in rosbags' ROS 2 Jazzy type store, and prints
{"rosbags": its version, "hashes": {type name: hash}} as JSON.
"""

import json
import sys
from importlib.metadata import version

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

request = json.load(sys.stdin)
store = get_typestore(Stores.ROS2_JAZZY)
types = {}
for name, text in request["register"].items():
    types.update(get_types_from_msg(text, name))
store.register(types)
hashes = {name: store.hash_rihs01(name) for name in request["hash"]}
json.dump({"rosbags": version("rosbags"), "hashes": hashes}, sys.stdout)
