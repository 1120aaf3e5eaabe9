"""Reads a cutlab recording with the `mcap` package from PyPI (CRC checks on) and decodes
its Foxglove protobuf poses with `mcap-protobuf-support`, from the schema in the file.
Prints message counts per topic, the first pose and tool state, metadata and attachment names
as JSON (checked by recorder/tests/recording.rs)."""
import json
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

path = sys.argv[1]
counts = {}
first_pose = None
first_state = None
with open(path, "rb") as f:
    reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
    for schema, channel, message, decoded in reader.iter_decoded_messages(
        topics=["/tool/pose", "/tissue/surface"]
    ):
        if channel.topic == "/tool/pose" and first_pose is None:
            p = decoded.pose.position
            first_pose = [p.x, p.y, p.z]
    for schema, channel, message in reader.iter_messages():
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
        if channel.topic == "/tool/state" and first_state is None:
            first_state = json.loads(message.data)
    metadata = [m.name for m in reader.iter_metadata()]
    attachments = [a.name for a in reader.iter_attachments()]
json.dump(
    {
        "counts": counts,
        "first_pose_xyz": first_pose,
        "first_tool_state": first_state,
        "metadata": metadata,
        "attachments": attachments,
    },
    sys.stdout,
)
