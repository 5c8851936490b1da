/* SPDX-License-Identifier: LGPL-2.1-or-later */
/**
 * SECTION:element-lftagpublish
 * @title: lftagpublish
 *
 * Writes the LFTag detections of every buffer that carries an LFTagMeta (put
 * there by lftagdetect) as one line of JSON (JSON Lines) to a file or to the
 * standard output, and passes the buffers on untouched. It takes any caps, so it
 * can sit anywhere downstream of lftagdetect where the meta still is: after
 * videoconvert, videoscale, queue and tee, and after a video encoder (encoded
 * buffers keep the meta). Muxers, files and network protocols do not carry
 * metas: put lftagpublish before them.
 *
 * Each line holds, in this order: "frame" (the buffer's number in the stream
 * since the element started, from 0, counting buffers without a meta too; with
 * frame-numbers=stream-time, round(stream time x frame rate), the frame's index
 * in the file even after frames were lost, as `lftag annotate` writes it),
 * "pts", "time" (the pts in seconds), "dts", "duration", "running_time",
 * "stream_time" (nanoseconds; null when unknown), "width" and "height" (the
 * frame the points are in: the analysed one, or the scaled one after
 * videoscale), "analysed" (false for a frame lftagdetect passed on without
 * detection: late under late-frames=skip, or unreadable; its empty detections
 * say nothing about markers) and "detections", each as `lftag detect` prints it
 * (the values of lftag-meta.h's detection structure under underscored names,
 * the pose's under "pose", plus "id_hex"; docs/cli.md, "JSON output"). A buffer without an
 * LFTagMeta writes no line (the element warns once per stream).
 *
 * To join a line with its frame in a file, use "stream_time": the frame's position
 * in the stream, from 0 at the start of the file, whatever offset the pts carries
 * (x264enc adds 1000 hours to its output's pts and starts its segment there, so
 * after it "pts" and "time" are 3600000 s on, while "stream_time" is not).
 * "running_time" is the pipeline clock's (it starts again from 0 after a seek): use
 * it to line the detections up with other streams of the same pipeline.
 *
 * A location that cannot be opened for writing fails the state change to PAUSED
 * with an error naming it. Each line goes to the kernel whole, in one write(2)
 * (continued after a short write or a signal), with nothing buffered in the
 * element. A write that fails (a full disk, a file size limit) is an error that
 * says why and which frame's line is lost, and the file is cut back to its last
 * whole line, so that it holds whole lines only; on the standard output, which
 * lftagpublish does not truncate, the error says whether part of the line went
 * out. Before each line, at EOS and when stopping, the element checks that the
 * file it writes is still the one at the location: deleted (or its directory
 * removed), renamed away or replaced by another file is an error naming the
 * location and how many frames' lines are not there. After an error nothing more
 * is written and the file is kept as it is (whole lines only); it is closed when
 * the element stops.
 *
 * At EOS, and when the element stops without one (set to READY or NULL in the
 * middle of the stream, or after an error elsewhere in the pipeline), every buffer
 * received has its whole line in the file; the file is then put on the disk
 * (fdatasync; a disk that fails to is an error) and, when stopping, closed.
 *
 * ## MQTT
 *
 * With target=mqtt (a build with libmosquitto, Debian's libmosquitto-dev) each
 * line goes instead as one MQTT message, the same JSON without the newline, to
 * broker on topic ("lftag/{camera}/detections" by default, {camera} standing for
 * the camera property: give each camera its own). Settings that cannot work (a
 * malformed broker address, a topic with wildcards, a TLS file that cannot be
 * read, a build without libmosquitto) fail the start with an error saying what to
 * fix; a broker that refuses the connection (credentials, client id) is an error
 * too. A broker that is not there, or goes away, is a warning: the element
 * reconnects in the background (after 1 s, then twice as long each time, at most
 * 30 s) and keeps up to queue-size frames' messages meanwhile, sent in order once
 * connected; when the queue is full the new frames' messages are dropped,
 * counted in the read-only dropped property, and a warning says so (once per
 * outage, and at EOS). The streaming thread never waits for the network. At EOS
 * the element waits up to flush-timeout for the queue to reach the broker. QoS 1
 * (the default) resends what the broker did not acknowledge, so a message may
 * arrive twice after a reconnection, never out of order; QoS 0 loses what was in
 * flight when the connection dropped.
 *
 * ## Example launch lines
 * |[
 * gst-launch-1.0 lftagtestsrc num-buffers=30 ! lftagdetect ! lftagpublish ! fakesink
 * ]| Thirty lines of JSON on the standard output.
 * |[
 * gst-launch-1.0 -e filesrc location=in.mp4 ! decodebin ! videoconvert ! \
 *     lftagdetect overlay=outline+id ! lftagpublish location=detections.jsonl ! \
 *     videoconvert ! x264enc ! mp4mux ! filesink location=out.mp4
 * ]| An annotated H.264 video and its detections beside it, each line keyed to its
 * frame by "stream_time" (and by "frame" while no frame is dropped).
 * |[
 * gst-launch-1.0 v4l2src ! videoconvert ! lftagdetect ! \
 *     lftagpublish target=mqtt broker=mqtt://broker.local camera=door ! fakesink
 * ]| A camera's detections on the topic lftag/door/detections.
 */
#include "gstlftagpublish.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <optional>
#include <string>

#include "lftagjson.h"
#if LFTAG_HAVE_MQTT
#include "mqttsender.h"
#endif

GST_DEBUG_CATEGORY_STATIC(gst_lftag_publish_debug);
#define GST_CAT_DEFAULT gst_lftag_publish_debug

enum {
  PROP_0,
  PROP_LOCATION,
  PROP_APPEND,
  PROP_FRAME_NUMBERS,
  PROP_TARGET,
  PROP_BROKER,
  PROP_TOPIC,
  PROP_CAMERA,
  PROP_QOS,
  PROP_CLIENT_ID,
  PROP_USERNAME,
  PROP_PASSWORD,
  PROP_TLS_CA_FILE,
  PROP_TLS_CERT_FILE,
  PROP_TLS_KEY_FILE,
  PROP_QUEUE_SIZE,
  PROP_FLUSH_TIMEOUT,
  PROP_DROPPED,
};

/* Where the lines go. */
typedef enum {
  GST_LFTAG_PUBLISH_TARGET_FILE,
  GST_LFTAG_PUBLISH_TARGET_MQTT,
} GstLFTagPublishTarget;

#define GST_TYPE_LFTAG_PUBLISH_TARGET (gst_lftag_publish_target_get_type())
static GType gst_lftag_publish_target_get_type(void) {
  static const GEnumValue values[] = {
      {GST_LFTAG_PUBLISH_TARGET_FILE, "JSON Lines to location (a file, or the standard output)", "file"},
      {GST_LFTAG_PUBLISH_TARGET_MQTT, "One MQTT message per frame to broker, on topic", "mqtt"},
      {0, nullptr, nullptr},
  };
  static const GType type = g_enum_register_static("GstLFTagPublishTarget", values);
  return type;
}

/* What "frame" counts. */
typedef enum {
  GST_LFTAG_PUBLISH_FRAME_NUMBERS_COUNT,
  GST_LFTAG_PUBLISH_FRAME_NUMBERS_STREAM_TIME,
} GstLFTagPublishFrameNumbers;

#define GST_TYPE_LFTAG_PUBLISH_FRAME_NUMBERS (gst_lftag_publish_frame_numbers_get_type())
static GType gst_lftag_publish_frame_numbers_get_type(void) {
  static const GEnumValue values[] = {
      {GST_LFTAG_PUBLISH_FRAME_NUMBERS_COUNT, "The buffer's number since the element started", "count"},
      {GST_LFTAG_PUBLISH_FRAME_NUMBERS_STREAM_TIME,
       "round(stream time x frame rate): the frame's index in the file, after a gap too", "stream-time"},
      {0, nullptr, nullptr},
  };
  static const GType type = g_enum_register_static("GstLFTagPublishFrameNumbers", values);
  return type;
}

#define DEFAULT_PROP_LOCATION nullptr
#define DEFAULT_PROP_APPEND FALSE
#define DEFAULT_PROP_FRAME_NUMBERS GST_LFTAG_PUBLISH_FRAME_NUMBERS_COUNT
#define DEFAULT_PROP_TARGET GST_LFTAG_PUBLISH_TARGET_FILE
#define DEFAULT_PROP_BROKER "localhost:1883"
#define DEFAULT_PROP_TOPIC "lftag/{camera}/detections"
#define DEFAULT_PROP_QOS 1
#define DEFAULT_PROP_QUEUE_SIZE 1000
#define DEFAULT_PROP_FLUSH_TIMEOUT 5000

static GstStaticPadTemplate sink_template =
    GST_STATIC_PAD_TEMPLATE("sink", GST_PAD_SINK, GST_PAD_ALWAYS, GST_STATIC_CAPS_ANY);
static GstStaticPadTemplate src_template =
    GST_STATIC_PAD_TEMPLATE("src", GST_PAD_SRC, GST_PAD_ALWAYS, GST_STATIC_CAPS_ANY);

struct _GstLFTagPublish {
  GstBaseTransform parent;

  /* Properties, under the object lock. */
  gchar* location;
  gboolean append;
  GstLFTagPublishFrameNumbers frame_numbers;
  GstLFTagPublishTarget target;
  gchar *broker, *topic, *camera, *client_id, *username, *password;
  gchar *tls_ca_file, *tls_cert_file, *tls_key_file;
  guint qos, queue_size, flush_timeout;

  /* The MQTT target, made in start(), ended in stop(); the pointer under the object lock. */
#if LFTAG_HAVE_MQTT
  lftag::gst::MqttSender* mqtt;
#endif
  guint64 dropped; /* of the last run, once stopped */

  /* Streaming state: opened in start(), closed in stop(). */
  int fd;             /* -1: none */
  gboolean to_stdout; /* fd is the standard output: never closed, cut or checked */
  gchar* path;        /* the file's absolute path, for the identity check; null for stdout */
  gchar* opened;      /* the location as opened, for messages */
  dev_t dev;          /* the identity of the file opened */
  ino_t ino;
  guint64 frame;
  gint fps_n, fps_d; /* from the caps; fps_n 0: unknown or variable */
  guint64 lines;     /* whole lines written since the start */
  guint64 synced;    /* lines known to be on the disk (fdatasync'd) */
  gboolean failed;   /* an error was posted: nothing more is written */
  guint64 unwritten; /* buffers refused after the error */
  gboolean warned_no_meta;
};

static void gst_lftag_publish_set_property(GObject* object, guint prop_id, const GValue* value, GParamSpec* pspec);
static void gst_lftag_publish_get_property(GObject* object, guint prop_id, GValue* value, GParamSpec* pspec);
static void gst_lftag_publish_finalize(GObject* object);
static gboolean gst_lftag_publish_start(GstBaseTransform* trans);
static gboolean gst_lftag_publish_stop(GstBaseTransform* trans);
static gboolean gst_lftag_publish_sink_event(GstBaseTransform* trans, GstEvent* event);
static gboolean gst_lftag_publish_set_caps(GstBaseTransform* trans, GstCaps* incaps, GstCaps* outcaps);
static GstFlowReturn gst_lftag_publish_transform_ip(GstBaseTransform* trans, GstBuffer* buffer);

#define gst_lftag_publish_parent_class parent_class
G_DEFINE_TYPE(GstLFTagPublish, gst_lftag_publish, GST_TYPE_BASE_TRANSFORM);
GST_ELEMENT_REGISTER_DEFINE(lftagpublish, "lftagpublish", GST_RANK_NONE, GST_TYPE_LFTAG_PUBLISH);

static void gst_lftag_publish_class_init(GstLFTagPublishClass* klass) {
  GObjectClass* gobject_class = G_OBJECT_CLASS(klass);
  GstElementClass* element_class = GST_ELEMENT_CLASS(klass);
  GstBaseTransformClass* trans_class = GST_BASE_TRANSFORM_CLASS(klass);
  const auto ready = GParamFlags(G_PARAM_READWRITE | G_PARAM_STATIC_STRINGS | GST_PARAM_MUTABLE_READY);

  GST_DEBUG_CATEGORY_INIT(gst_lftag_publish_debug, "lftagpublish", 0, "LFTag detections as JSON Lines");

  gobject_class->set_property = gst_lftag_publish_set_property;
  gobject_class->get_property = gst_lftag_publish_get_property;
  gobject_class->finalize = gst_lftag_publish_finalize;

  g_object_class_install_property(
      gobject_class, PROP_LOCATION,
      g_param_spec_string("location", "Location",
                          "File to write the JSON Lines to; unset, empty or \"-\": the standard output",
                          DEFAULT_PROP_LOCATION, ready));
  g_object_class_install_property(gobject_class, PROP_APPEND,
                                  g_param_spec_boolean("append", "Append", "Append to the file instead of replacing it",
                                                       DEFAULT_PROP_APPEND, ready));
  g_object_class_install_property(
      gobject_class, PROP_FRAME_NUMBERS,
      g_param_spec_enum("frame-numbers", "Frame numbers",
                        "What \"frame\" counts: count, the buffers since the start; stream-time, round(stream "
                        "time x frame rate), the frame's index in the file even after frames are lost (the count "
                        "without a frame rate in the caps)",
                        GST_TYPE_LFTAG_PUBLISH_FRAME_NUMBERS, DEFAULT_PROP_FRAME_NUMBERS, ready));
  gst_type_mark_as_plugin_api(GST_TYPE_LFTAG_PUBLISH_FRAME_NUMBERS, GstPluginAPIFlags(0));

  /* The MQTT target. */
  g_object_class_install_property(
      gobject_class, PROP_TARGET,
      g_param_spec_enum("target", "Target",
                        "Where the detections go: file (JSON Lines to location) or mqtt (one message per frame to "
                        "broker, on topic; needs a build with libmosquitto)",
                        GST_TYPE_LFTAG_PUBLISH_TARGET, DEFAULT_PROP_TARGET, ready));
  gst_type_mark_as_plugin_api(GST_TYPE_LFTAG_PUBLISH_TARGET, GstPluginAPIFlags(0));
  const auto string = [&](guint id, const char* name, const char* nick, const char* blurb, const char* value,
                          GParamFlags flags) {
    g_object_class_install_property(gobject_class, id, g_param_spec_string(name, nick, blurb, value, flags));
  };
  string(PROP_BROKER, "broker", "Broker",
         "MQTT broker: HOST, HOST:PORT, mqtt://HOST[:PORT] or mqtts://HOST[:PORT] (TLS; port 8883 by default)",
         DEFAULT_PROP_BROKER, ready);
  string(PROP_TOPIC, "topic", "Topic", "MQTT topic; {camera} stands for the camera property", DEFAULT_PROP_TOPIC,
         ready);
  string(PROP_CAMERA, "camera", "Camera",
         "Name of this stream in the topic ({camera}); unset: the element's name. Give each camera its own", nullptr,
         ready);
  g_object_class_install_property(
      gobject_class, PROP_QOS,
      g_param_spec_uint("qos", "QoS",
                        "MQTT quality of service: 0 at most once (lost while the connection drops), 1 at least once "
                        "(resent until acknowledged), 2 exactly once",
                        0, 2, DEFAULT_PROP_QOS, ready));
  string(PROP_CLIENT_ID, "client-id", "Client id", "MQTT client id, unique per broker; unset: lftag-CAMERA-PID",
         nullptr, ready);
  string(PROP_USERNAME, "username", "Username", "MQTT username; unset: none", nullptr, ready);
  string(PROP_PASSWORD, "password", "Password", "MQTT password (needs username); write-only", nullptr,
         GParamFlags(G_PARAM_WRITABLE | G_PARAM_STATIC_STRINGS | GST_PARAM_MUTABLE_READY));
  string(PROP_TLS_CA_FILE, "tls-ca-file", "TLS CA file",
         "PEM file of the CA that signed the broker's certificate; turns TLS on (mqtts:// without it: the "
         "system's CAs)",
         nullptr, ready);
  string(PROP_TLS_CERT_FILE, "tls-cert-file", "TLS certificate file",
         "PEM client certificate, for brokers that require one (with tls-key-file)", nullptr, ready);
  string(PROP_TLS_KEY_FILE, "tls-key-file", "TLS key file", "PEM private key of tls-cert-file, unencrypted", nullptr,
         ready);
  g_object_class_install_property(
      gobject_class, PROP_QUEUE_SIZE,
      g_param_spec_uint("queue-size", "Queue size",
                        "Frames' messages kept while the broker is away (at 30 fps, 1000 is 33 s); once full the "
                        "new ones are dropped and counted in dropped",
                        1, 10000000, DEFAULT_PROP_QUEUE_SIZE, ready));
  g_object_class_install_property(
      gobject_class, PROP_FLUSH_TIMEOUT,
      g_param_spec_uint("flush-timeout", "Flush timeout",
                        "At EOS, how long to wait (ms) for the queued messages to reach the broker; what has not "
                        "is reported and lost when stopping",
                        0, G_MAXUINT, DEFAULT_PROP_FLUSH_TIMEOUT,
                        GParamFlags(G_PARAM_READWRITE | G_PARAM_STATIC_STRINGS | GST_PARAM_MUTABLE_PLAYING)));
  g_object_class_install_property(
      gobject_class, PROP_DROPPED,
      g_param_spec_uint64("dropped", "Dropped",
                          "Frames whose MQTT message was dropped since the start, the queue being full while the "
                          "broker was away",
                          0, G_MAXUINT64, 0, GParamFlags(G_PARAM_READABLE | G_PARAM_STATIC_STRINGS)));

  gst_element_class_set_static_metadata(element_class, "LFTag detections as JSON Lines", "Filter/Metadata",
                                        "Writes the LFTag detections of each buffer (its LFTagMeta, from lftagdetect) "
                                        "with its timestamps as one JSON line to a file, the standard output or an "
                                        "MQTT broker, and passes the buffers on untouched",
                                        LFTAG_AUTHOR);
  gst_element_class_add_static_pad_template(element_class, &sink_template);
  gst_element_class_add_static_pad_template(element_class, &src_template);

  trans_class->start = GST_DEBUG_FUNCPTR(gst_lftag_publish_start);
  trans_class->stop = GST_DEBUG_FUNCPTR(gst_lftag_publish_stop);
  trans_class->sink_event = GST_DEBUG_FUNCPTR(gst_lftag_publish_sink_event);
  trans_class->set_caps = GST_DEBUG_FUNCPTR(gst_lftag_publish_set_caps);
  trans_class->transform_ip = GST_DEBUG_FUNCPTR(gst_lftag_publish_transform_ip);
}

static void gst_lftag_publish_init(GstLFTagPublish* self) {
  self->location = nullptr;
  self->append = DEFAULT_PROP_APPEND;
  self->frame_numbers = DEFAULT_PROP_FRAME_NUMBERS;
  self->target = DEFAULT_PROP_TARGET;
  self->broker = g_strdup(DEFAULT_PROP_BROKER);
  self->topic = g_strdup(DEFAULT_PROP_TOPIC);
  self->qos = DEFAULT_PROP_QOS;
  self->queue_size = DEFAULT_PROP_QUEUE_SIZE;
  self->flush_timeout = DEFAULT_PROP_FLUSH_TIMEOUT;
  self->fps_n = 0;
  self->fps_d = 1;
  self->fd = -1;
  self->to_stdout = FALSE;
  self->path = nullptr;
  self->opened = nullptr;
  /* Like identity: buffers pass untouched, transform_ip only looks at them. */
  gst_base_transform_set_passthrough(GST_BASE_TRANSFORM(self), TRUE);
  gst_base_transform_set_gap_aware(GST_BASE_TRANSFORM(self), TRUE);
}

static void gst_lftag_publish_finalize(GObject* object) {
  GstLFTagPublish* self = GST_LFTAG_PUBLISH(object);

  g_free(self->location);
  for (gchar* text : {self->broker, self->topic, self->camera, self->client_id, self->username, self->password,
                      self->tls_ca_file, self->tls_cert_file, self->tls_key_file})
    g_free(text);
  g_free(self->path);
  g_free(self->opened);
  G_OBJECT_CLASS(parent_class)->finalize(object);
}

/* The field of a string property of the MQTT target; null for any other. */
static gchar** gst_lftag_publish_string_field(GstLFTagPublish* self, guint prop_id) {
  switch (prop_id) {
    case PROP_BROKER: return &self->broker;
    case PROP_TOPIC: return &self->topic;
    case PROP_CAMERA: return &self->camera;
    case PROP_CLIENT_ID: return &self->client_id;
    case PROP_USERNAME: return &self->username;
    case PROP_PASSWORD: return &self->password;
    case PROP_TLS_CA_FILE: return &self->tls_ca_file;
    case PROP_TLS_CERT_FILE: return &self->tls_cert_file;
    case PROP_TLS_KEY_FILE: return &self->tls_key_file;
    default: return nullptr;
  }
}

static void gst_lftag_publish_set_property(GObject* object, guint prop_id, const GValue* value, GParamSpec* pspec) {
  GstLFTagPublish* self = GST_LFTAG_PUBLISH(object);

  GST_OBJECT_LOCK(self);
  switch (prop_id) {
    case PROP_LOCATION:
      g_free(self->location);
      self->location = g_value_dup_string(value);
      break;
    case PROP_APPEND: self->append = g_value_get_boolean(value); break;
    case PROP_FRAME_NUMBERS: self->frame_numbers = GstLFTagPublishFrameNumbers(g_value_get_enum(value)); break;
    case PROP_TARGET: self->target = GstLFTagPublishTarget(g_value_get_enum(value)); break;
    case PROP_QOS: self->qos = g_value_get_uint(value); break;
    case PROP_QUEUE_SIZE: self->queue_size = g_value_get_uint(value); break;
    case PROP_FLUSH_TIMEOUT: self->flush_timeout = g_value_get_uint(value); break;
    default: {
      gchar** text = gst_lftag_publish_string_field(self, prop_id);
      if (text) {
        g_free(*text);
        *text = g_value_dup_string(value);
      } else {
        G_OBJECT_WARN_INVALID_PROPERTY_ID(object, prop_id, pspec);
      }
      break;
    }
  }
  GST_OBJECT_UNLOCK(self);
}

static void gst_lftag_publish_get_property(GObject* object, guint prop_id, GValue* value, GParamSpec* pspec) {
  GstLFTagPublish* self = GST_LFTAG_PUBLISH(object);

  GST_OBJECT_LOCK(self);
  switch (prop_id) {
    case PROP_LOCATION: g_value_set_string(value, self->location); break;
    case PROP_APPEND: g_value_set_boolean(value, self->append); break;
    case PROP_FRAME_NUMBERS: g_value_set_enum(value, self->frame_numbers); break;
    case PROP_TARGET: g_value_set_enum(value, self->target); break;
    case PROP_QOS: g_value_set_uint(value, self->qos); break;
    case PROP_QUEUE_SIZE: g_value_set_uint(value, self->queue_size); break;
    case PROP_FLUSH_TIMEOUT: g_value_set_uint(value, self->flush_timeout); break;
    case PROP_DROPPED:
#if LFTAG_HAVE_MQTT
      g_value_set_uint64(value, self->mqtt ? self->mqtt->dropped() : self->dropped);
#else
      g_value_set_uint64(value, self->dropped);
#endif
      break;
    default: {
      gchar** text = gst_lftag_publish_string_field(self, prop_id);
      if (text && prop_id != PROP_PASSWORD)
        g_value_set_string(value, *text);
      else
        G_OBJECT_WARN_INVALID_PROPERTY_ID(object, prop_id, pspec);
      break;
    }
  }
  GST_OBJECT_UNLOCK(self);
}

/* The MQTT target: the settings checked (an error saying what to fix when they cannot
 * work) and the client started; it connects in the background. */
static gboolean gst_lftag_publish_start_mqtt(GstLFTagPublish* self) {
#if LFTAG_HAVE_MQTT
  const auto text = [](const gchar* value) { return std::string(value ? value : ""); };
  lftag::gst::MqttSettings settings;
  GST_OBJECT_LOCK(self);
  const std::string broker = text(self->broker);
  std::string camera = text(self->camera);
  if (camera.empty()) camera = GST_OBJECT_NAME(self);
  std::string topic = text(self->topic);
  settings.client_id = text(self->client_id);
  settings.username = text(self->username);
  settings.password = text(self->password);
  settings.ca_file = text(self->tls_ca_file);
  settings.cert_file = text(self->tls_cert_file);
  settings.key_file = text(self->tls_key_file);
  settings.qos = int(self->qos);
  settings.queue_size = self->queue_size;
  GST_OBJECT_UNLOCK(self);

  std::string why;
  if (!lftag::gst::parse_broker(broker, settings, why)) {
    GST_ELEMENT_ERROR(self, RESOURCE, SETTINGS, ("Bad broker \"%s\": %s.", broker.c_str(), why.c_str()), (nullptr));
    return FALSE;
  }
  for (std::size_t at; (at = topic.find("{camera}")) != std::string::npos;) topic.replace(at, 8, camera);
  settings.topic = topic;
  if (settings.client_id.empty()) settings.client_id = "lftag-" + camera + "-" + std::to_string(getpid());
  auto* sender = new lftag::gst::MqttSender(GST_ELEMENT(self));
  if (!sender->start(settings, why)) {
    delete sender;
    GST_ELEMENT_ERROR(self, RESOURCE, SETTINGS, ("Cannot publish to MQTT: %s.", why.c_str()),
                      ("broker %s:%d, topic %s", settings.host.c_str(), settings.port, settings.topic.c_str()));
    return FALSE;
  }
  GST_OBJECT_LOCK(self);
  self->mqtt = sender;
  GST_OBJECT_UNLOCK(self);
  return TRUE;
#else
  GST_ELEMENT_ERROR(self, RESOURCE, SETTINGS,
                    ("This lftagpublish was built without MQTT (no libmosquitto, or -Dmqtt=disabled): install "
                     "libmosquitto-dev and rebuild, or use target=file."),
                    (nullptr));
  return FALSE;
#endif
}

static gboolean gst_lftag_publish_start(GstBaseTransform* trans) {
  GstLFTagPublish* self = GST_LFTAG_PUBLISH(trans);

  GST_OBJECT_LOCK(self);
  const std::string location = self->location ? self->location : "";
  const gboolean append = self->append;
  const bool mqtt = self->target == GST_LFTAG_PUBLISH_TARGET_MQTT;
  self->dropped = 0;
  GST_OBJECT_UNLOCK(self);

  self->frame = 0;
  self->lines = 0;
  self->synced = 0;
  self->failed = FALSE;
  self->unwritten = 0;
  self->warned_no_meta = FALSE;
  g_clear_pointer(&self->path, g_free);
  g_clear_pointer(&self->opened, g_free);
  if (mqtt) return gst_lftag_publish_start_mqtt(self);
  if (location.empty() || location == "-") {
    /* The lines go to the descriptor, not through stdio: whatever the
     * application printed before goes out first. */
    fflush(stdout);
    self->fd = STDOUT_FILENO;
    self->to_stdout = TRUE;
    self->opened = g_strdup("the standard output");
    return TRUE;
  }
  self->to_stdout = FALSE;
  self->fd = open(location.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC | (append ? O_APPEND : O_TRUNC), 0666);
  struct stat st;
  if (self->fd < 0 || fstat(self->fd, &st) != 0) {
    const int error = errno;
    if (self->fd >= 0) close(self->fd);
    self->fd = -1;
    GST_ELEMENT_ERROR(self, RESOURCE, OPEN_WRITE,
                      ("Could not open \"%s\" for writing: %s.", location.c_str(), g_strerror(error)), (nullptr));
    return FALSE;
  }
  self->dev = st.st_dev;
  self->ino = st.st_ino;
  /* Absolute, so that the check finds the same file if the process changes
   * its working directory. */
  if (g_path_is_absolute(location.c_str())) {
    self->path = g_strdup(location.c_str());
  } else {
    gchar* here = g_get_current_dir();
    self->path = g_build_filename(here, location.c_str(), nullptr);
    g_free(here);
  }
  self->opened = g_strdup_printf("\"%s\"", location.c_str());
  GST_INFO_OBJECT(self, "writing to %s (%s)", self->opened, self->path);
  return TRUE;
}

/* "the line of 1 frame", "the lines of 12 frames". */
static std::string frames_lines(guint64 n) {
  return n == 1 ? "the line of 1 frame" : "the lines of " + std::to_string(n) + " frames";
}

/* Whether the file written is still the one at the location: not deleted (or its
 * directory removed), renamed away or replaced. When it is not, posts an error
 * naming the location and how many frames' lines are not there: the lines
 * written, and `pending` more that were to be. An fstat and a stat, a few
 * microseconds, once per line. */
static gboolean gst_lftag_publish_check_file(GstLFTagPublish* self, guint64 pending) {
  if (self->fd < 0 || self->to_stdout || self->failed) return TRUE;

  struct stat open_st, path_st;
  if (fstat(self->fd, &open_st) != 0) {
    GST_WARNING_OBJECT(self, "cannot fstat %s: %s", self->opened, g_strerror(errno));
    return TRUE;
  }
  const guint64 lost = self->lines + pending;
  const std::string frames = frames_lines(lost);
  const char* are = lost == 1 ? "is" : "are";
  gchar* debug =
      g_strdup_printf("%s: device %" G_GUINT64_FORMAT ", inode %" G_GUINT64_FORMAT ", %u links; %" G_GUINT64_FORMAT
                      " lines written to it",
                      self->path, guint64(self->dev), guint64(self->ino), guint(open_st.st_nlink), self->lines);
  /* The path first: a file renamed over ours also leaves ours with no link. */
  gboolean same = FALSE;
  const int found = stat(self->path, &path_st) == 0 ? 0 : errno;
  if (found == 0 && (path_st.st_dev != self->dev || path_st.st_ino != self->ino)) {
    GST_ELEMENT_ERROR(self, RESOURCE, WRITE,
                      ("%s was replaced by another file while being written: %s %s not in it, and no more are "
                       "written.",
                       self->opened, frames.c_str(), are),
                      ("%s", debug));
  } else if (open_st.st_nlink == 0) {
    GST_ELEMENT_ERROR(
        self, RESOURCE, NOT_FOUND,
        ("%s was deleted while being written: %s %s lost, and no more are written.", self->opened, frames.c_str(), are),
        ("%s", debug));
  } else if (found == ENOENT || found == ENOTDIR) {
    GST_ELEMENT_ERROR(self, RESOURCE, NOT_FOUND,
                      ("%s is no longer there (renamed or removed while being written): %s %s not there, and no "
                       "more are written.",
                       self->opened, frames.c_str(), are),
                      ("%s", debug));
  } else {
    /* There, or not to be checked (say, a directory made unreadable: the file
     * may well be there). */
    if (found != 0) GST_WARNING_OBJECT(self, "cannot check that %s is still there: %s", self->path, g_strerror(found));
    same = TRUE;
  }
  g_free(debug);
  if (!same) self->failed = TRUE;
  return same;
}

/* Hands `line` to the kernel whole: write(2) until all of it is written,
 * through short writes and signals. On failure posts an error saying what
 * failed and that the line of `frame` is lost, after cutting the file back to
 * its last whole line (a file this element opened; the standard output is
 * never cut). */
static gboolean gst_lftag_publish_write_line(GstLFTagPublish* self, const std::string& line, guint64 frame) {
  std::size_t done = 0;
  int error = 0;
  while (done < line.size()) {
    const ssize_t n = write(self->fd, line.data() + done, line.size() - done);
    if (n > 0) {
      done += std::size_t(n);
    } else if (n < 0 && errno == EINTR) {
      continue;
    } else {
      error = n < 0 ? errno : EIO;
      break;
    }
  }
  if (done == line.size()) {
    ++self->lines;
    return TRUE;
  }

  /* The partial line ends at the descriptor's offset (the end of the file,
   * appending or not): cutting `done` bytes before it leaves the last whole
   * line at the end. */
  std::string holds = self->to_stdout ? "nothing of it went out" : "the file holds whole lines only";
  std::string cut;
  if (done > 0 && self->to_stdout) {
    holds = "the standard output ends with part of it";
  } else if (done > 0) {
    const off_t end = lseek(self->fd, 0, SEEK_CUR);
    int cut_error = 0;
    if (end < 0)
      cut_error = errno;
    else if (end < off_t(done))
      cut_error = EINVAL;
    else if (ftruncate(self->fd, end - off_t(done)) != 0)
      cut_error = errno;
    if (cut_error == 0) {
      lseek(self->fd, end - off_t(done), SEEK_SET);
      cut = "; cut back to " + std::to_string(end - off_t(done)) + " bytes";
    } else {
      holds = std::string("the file ends with part of it (cutting it off failed: ") + g_strerror(cut_error) + ")";
    }
  }
  gchar* text = g_strdup_printf("Could not write to %s: %s. 1 frame lost (the line of frame %" G_GUINT64_FORMAT
                                ") and no more written; %s.",
                                self->opened, g_strerror(error), frame, holds.c_str());
  gchar* debug = g_strdup_printf("%zu of the line's %zu bytes written after %" G_GUINT64_FORMAT " whole lines%s", done,
                                 line.size(), self->lines, cut.c_str());
  if (error == ENOSPC || error == EDQUOT)
    GST_ELEMENT_ERROR(self, RESOURCE, NO_SPACE_LEFT, ("%s", text), ("%s", debug));
  else
    GST_ELEMENT_ERROR(self, RESOURCE, WRITE, ("%s", text), ("%s", debug));
  g_free(text);
  g_free(debug);
  self->failed = TRUE;
  return FALSE;
}

/* Puts the lines written since the last call on the disk (fdatasync): at EOS and when
 * stopping, so that the file is whole even if the machine goes down right after the
 * pipeline ends. A file that cannot take it (a pipe, /dev/null) is not an error; a disk
 * that fails to write is, naming the location and how many lines may not be on it. */
static gboolean gst_lftag_publish_sync(GstLFTagPublish* self) {
  if (self->fd < 0 || self->to_stdout || self->failed || self->synced == self->lines) return TRUE;
  if (fdatasync(self->fd) == 0 || errno == EINVAL || errno == EROFS) {
    self->synced = self->lines;
    return TRUE;
  }
  const int error = errno;
  const guint64 unsure = self->lines - self->synced;
  const std::string frames = frames_lines(unsure);
  GST_ELEMENT_ERROR(
      self, RESOURCE, SYNC,
      ("Could not flush %s to the disk: %s; %s may not be on it.", self->opened, g_strerror(error), frames.c_str()),
      ("fdatasync after %" G_GUINT64_FORMAT " lines, %" G_GUINT64_FORMAT " of them synced before", self->lines,
       self->synced));
  self->failed = TRUE;
  return FALSE;
}

static gboolean gst_lftag_publish_stop(GstBaseTransform* trans) {
  GstLFTagPublish* self = GST_LFTAG_PUBLISH(trans);

#if LFTAG_HAVE_MQTT
  GST_OBJECT_LOCK(self);
  lftag::gst::MqttSender* sender = self->mqtt;
  self->mqtt = nullptr;
  if (sender) self->dropped = sender->dropped();
  GST_OBJECT_UNLOCK(self);
  if (sender) {
    sender->stop();
    delete sender;
    return TRUE;
  }
#endif

  /* Stopped without EOS (set to NULL or READY mid-stream, or after an error
   * elsewhere): every line received is already in the file; a file gone since the
   * last line is still reported, and the rest is put on the disk. */
  if (gst_lftag_publish_check_file(self, 0)) gst_lftag_publish_sync(self);
  if (self->unwritten > 0)
    GST_WARNING_OBJECT(self, "%" G_GUINT64_FORMAT " buffers came after the error and were not written",
                       self->unwritten);
  if (self->fd >= 0 && !self->to_stdout && close(self->fd) != 0) {
    GST_ELEMENT_ERROR(self, RESOURCE, CLOSE, ("Could not close %s: %s.", self->opened, g_strerror(errno)), (nullptr));
  }
  self->fd = -1;
  /* Stopping succeeds whatever happened to the file (the error is posted):
   * the pipeline must be able to reach NULL. */
  return TRUE;
}

static gboolean gst_lftag_publish_sink_event(GstBaseTransform* trans, GstEvent* event) {
  GstLFTagPublish* self = GST_LFTAG_PUBLISH(trans);

#if LFTAG_HAVE_MQTT
  /* At EOS the queue is given flush-timeout to reach the broker; the element says what
   * did not, and what was dropped. The EOS goes on either way: the frames went through. */
  if (GST_EVENT_TYPE(event) == GST_EVENT_EOS && self->mqtt) {
    GST_OBJECT_LOCK(self);
    const guint timeout = self->flush_timeout;
    GST_OBJECT_UNLOCK(self);
    const std::size_t left = self->mqtt->flush(std::chrono::milliseconds(timeout));
    const guint64 dropped = self->mqtt->dropped();
    if (left > 0)
      GST_ELEMENT_WARNING(self, RESOURCE, WRITE,
                          ("At the end of the stream %zu frames' MQTT messages had not reached the broker after "
                           "%u ms (flush-timeout): they are lost when the element stops.",
                           left, timeout),
                          (nullptr));
    if (dropped > 0)
      GST_ELEMENT_WARNING(self, RESOURCE, WRITE,
                          ("%" G_GUINT64_FORMAT " frames' MQTT messages were dropped while the broker was away "
                           "(queue-size); the dropped property has the count.",
                           dropped),
                          (nullptr));
  }
#endif

  /* Every line is written as it comes, so at EOS everything is in the file and
   * only has to be put on the disk; an EOS after an error, on a file that is
   * gone or on a disk that fails, goes no further, so that
   * the application does not take the output for complete. */
  if (GST_EVENT_TYPE(event) == GST_EVENT_EOS &&
      (self->failed || !gst_lftag_publish_check_file(self, 0) || !gst_lftag_publish_sync(self))) {
    gst_event_unref(event);
    return FALSE;
  }
  return GST_BASE_TRANSFORM_CLASS(parent_class)->sink_event(trans, event);
}

/* Any caps: raw or encoded video both give their frame rate. */
static gboolean gst_lftag_publish_set_caps(GstBaseTransform* trans, GstCaps* incaps, GstCaps*) {
  GstLFTagPublish* self = GST_LFTAG_PUBLISH(trans);
  gint n = 0, d = 1;
  if (gst_caps_get_size(incaps) == 0 ||
      !gst_structure_get_fraction(gst_caps_get_structure(incaps, 0), "framerate", &n, &d) || n <= 0 || d <= 0) {
    n = 0;
    d = 1;
  }
  self->fps_n = n;
  self->fps_d = d;
  return TRUE;
}

/* The "frame" of `buffer`: the count, or with frame-numbers=stream-time its stream time
 * in frames, so that a frame keeps the number it has in the file when frames before it
 * were lost (a damaged file, a decoder error). */
static guint64 gst_lftag_publish_frame_number(GstLFTagPublish* self, GstBaseTransform* trans, GstBuffer* buffer,
                                              guint64 count) {
  GST_OBJECT_LOCK(self);
  const bool by_time = self->frame_numbers == GST_LFTAG_PUBLISH_FRAME_NUMBERS_STREAM_TIME;
  GST_OBJECT_UNLOCK(self);
  if (!by_time || self->fps_n == 0 || trans->segment.format != GST_FORMAT_TIME || !GST_BUFFER_PTS_IS_VALID(buffer))
    return count;
  const GstClockTime t = gst_segment_to_stream_time(&trans->segment, GST_FORMAT_TIME, GST_BUFFER_PTS(buffer));
  if (!GST_CLOCK_TIME_IS_VALID(t)) return count;
  return gst_util_uint64_scale_round(t, guint64(self->fps_n), guint64(self->fps_d) * GST_SECOND);
}

static GstFlowReturn gst_lftag_publish_transform_ip(GstBaseTransform* trans, GstBuffer* buffer) {
  GstLFTagPublish* self = GST_LFTAG_PUBLISH(trans);
  const guint64 frame = gst_lftag_publish_frame_number(self, trans, buffer, self->frame++);

  if (self->failed) {
    ++self->unwritten;
    return GST_FLOW_ERROR;
  }
  std::optional<nlohmann::ordered_json> record;
  try {
    record = lftag::gst::buffer_json(buffer, trans->segment, frame);
  } catch (const std::exception& e) {
    GST_ELEMENT_WARNING(self, STREAM, DECODE, ("Malformed LFTagMeta: %s.", e.what()), ("on %" GST_PTR_FORMAT, buffer));
    return GST_FLOW_OK;
  }
  if (!record) {
    if (!self->warned_no_meta) {
      GST_ELEMENT_WARNING(self, STREAM, FORMAT,
                          ("A buffer without LFTagMeta came: lftagpublish writes the detections of "
                           "lftagdetect, which must be upstream (muxers and files do not keep the "
                           "meta, nor do videocrop and videobox, which cannot move its points)."),
                          ("first at %" GST_TIME_FORMAT, GST_TIME_ARGS(GST_BUFFER_PTS(buffer))));
      self->warned_no_meta = TRUE;
    }
    return GST_FLOW_OK;
  }

#if LFTAG_HAVE_MQTT
  /* Queued, never waited for: a broker away costs messages (counted), not frames. */
  if (self->mqtt) {
    self->mqtt->push(record->dump());
    return GST_FLOW_OK;
  }
#endif
  /* One whole line at a time, nothing kept back, so that a reader of a pipe or
   * of a growing file sees whole lines as the frames pass. */
  if (!gst_lftag_publish_check_file(self, 1) || !gst_lftag_publish_write_line(self, record->dump() + "\n", frame))
    return GST_FLOW_ERROR;
  return GST_FLOW_OK;
}
