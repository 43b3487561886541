"""VIDEO_STREAM_INFORMATION: a vehicle whose camera `cosim run --video`
streams describes the stream (type, URI, size, rate); one without says so."""

from __future__ import annotations

from mavtest import mavutil, of_type

from cosim.renderer.stream import VideoParticipant, VideoTarget


def test_the_vehicle_answers_video_stream_information(rig) -> None:
    ml = mavutil.mavlink
    r = rig(2)
    _, replies = r.request(lambda: r.gcs.mav.command_long_send(
        1, 1, ml.MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION, 0, 0, 0, 0, 0, 0, 0, 0))
    ack, = of_type(replies, "COMMAND_ACK")
    assert ack.result == ml.MAV_RESULT_FAILED  # nothing streamed yet
    info = VideoParticipant._info(VideoTarget(1, None, "127.0.0.1", 5600, "rtp"),
                                  type("Cam", (), {"rate_hz": 10, "width_px": 640,
                                                   "height_px": 480, "hfov_deg": 52.0,
                                                   "name": "belly"})(),
                                  "uav1")
    r.ep.set_video({1: [info]})
    _, replies = r.request(lambda: r.gcs.mav.command_long_send(
        1, 1, ml.MAV_CMD_REQUEST_MESSAGE, 0, ml.MAVLINK_MSG_ID_VIDEO_STREAM_INFORMATION, 0,
        0, 0, 0, 0, 0))
    vs, = of_type(replies, "VIDEO_STREAM_INFORMATION")
    assert (vs.stream_id, vs.count, vs.type, vs.uri, vs.name) == (
        1, 1, ml.VIDEO_STREAM_TYPE_RTPUDP, "udp://127.0.0.1:5600", "uav1/belly")
    assert (vs.resolution_h, vs.resolution_v, vs.framerate) == (640, 480, 10.0)
    assert vs.flags & ml.VIDEO_STREAM_STATUS_FLAGS_RUNNING
