"""Foxglove's messages read back as Foxglove reads them: protobuf, with the schema each channel
carries (a FileDescriptorSet, as the SDK's ``get_schema()`` gives it)."""

from __future__ import annotations

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory


def decoder(schema_name: str, data: bytes):
    """The protobuf message class of ``schema_name`` (``foxglove.SceneUpdate``) built from
    its FileDescriptorSet ``data``."""
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(data).file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))
