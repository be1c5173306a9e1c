"""An mcgnode bag's ParticleState messages by trajectory, decoded by `mcap` and
`mcap-ros2-support` (independently of mcgnode): shared by bag_to_gns.py and
bag_to_lagrangebench.py."""

from collections import defaultdict

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

TYPE = "mcgnode_msgs/msg/ParticleState"


def read_bag(path):
    """{trajectory_id: [ParticleState, ...]} in log order."""
    trajs = defaultdict(list)
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, _, _, msg in reader.iter_decoded_messages():
            if schema.name == TYPE:
                trajs[msg.trajectory_id].append(msg)
    return trajs
