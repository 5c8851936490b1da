// SPDX-License-Identifier: LGPL-2.1-or-later
// lftagpublish target=mqtt against a real mosquitto broker on a free loopback port: every
// frame's message arrives, in order, the same JSON as the file target's line; across a
// broker restart in the middle of a live stream what was queued arrives and what
// overflowed the queue is counted; settings that cannot work fail the start. Skipped
// (exit 77) only when the mosquitto binary is not installed. No timing assertions: every
// wait is for a condition, with a generous timeout.
// lftagdetect runs with deadline=0: its deadline's warning, which a loaded or sanitized
// machine can post, is not the subject here and would spoil the warning counts.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include <glib/gstdio.h>
#include <gst/gst.h>
#include <mosquitto.h>
#include <nlohmann/json.hpp>

// Last: check's macros (fail...) clash with names in the C++ library.
#include "check-main.h"
#include "errors.hpp"

namespace {

constexpr gint64 kTimeout = 60 * G_TIME_SPAN_SECOND;

// A port nobody listens on now.
int free_port() {
  const int s = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t size = sizeof a;
  fail_unless(bind(s, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
  fail_unless(getsockname(s, reinterpret_cast<sockaddr*>(&a), &size) == 0);
  close(s);
  return ntohs(a.sin_port);
}

bool accepts(int port) {
  const int s = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  const bool ok = connect(s, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  close(s);
  return ok;
}

// Waits (up to a minute) for `done`, checking every 20 ms.
template <typename F>
bool wait_until(F done) {
  const gint64 end = g_get_monotonic_time() + kTimeout;
  while (!done()) {
    if (g_get_monotonic_time() > end) return false;
    g_usleep(20000);
  }
  return true;
}

// mosquitto on 127.0.0.1:port, its config, log and persistence in a scratch directory.
// Persistent: a restart keeps the subscriber's session and the messages queued for it.
class Broker {
 public:
  Broker() : port_(free_port()) {
    gchar* dir = g_dir_make_tmp("lftag-mqtt-XXXXXX", nullptr);
    fail_unless(dir != nullptr);
    dir_ = dir;
    g_free(dir);
    std::ofstream(dir_ + "/mosquitto.conf") << "listener " << port_ << " 127.0.0.1\n"
                                            << "allow_anonymous true\n"
                                            // Started as root, mosquitto would become the
                                            // "mosquitto" user, who cannot write here.
                                            << "user " << g_get_user_name() << "\n"
                                            << "persistence true\n"
                                            << "persistence_location " << dir_ << "/\n"
                                            << "log_dest file " << dir_ << "/broker.log\n";
  }
  ~Broker() {
    stop();
    for (const char* name : {"mosquitto.conf", "broker.log", "mosquitto.db"}) g_unlink((dir_ + "/" + name).c_str());
    g_rmdir(dir_.c_str());
  }
  Broker(const Broker&) = delete;
  Broker& operator=(const Broker&) = delete;
  int port() const { return port_; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  void start() {
    const std::string config = dir_ + "/mosquitto.conf";
    const gchar* argv[] = {LFTAG_MOSQUITTO, "-c", config.c_str(), nullptr};
    GError* error = nullptr;
    fail_unless(g_spawn_async(nullptr, const_cast<gchar**>(argv), nullptr, G_SPAWN_DO_NOT_REAP_CHILD, nullptr, nullptr,
                              &pid_, &error),
                "cannot start mosquitto: %s", error ? error->message : "");
    fail_unless(wait_until([this] { return accepts(port_); }), "mosquitto does not listen on %d", port_);
  }
  // SIGTERM: mosquitto saves its sessions and queued messages, and exits.
  void stop() {
    if (pid_ <= 0) return;
    kill(pid_, SIGTERM);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = 0;
  }

 private:
  int port_;
  std::string dir_;
  GPid pid_ = 0;
};

// A subscriber with a persistent session, so that it misses nothing across a broker
// restart; it resubscribes at every connection.
class Subscriber {
 public:
  Subscriber(const Broker& broker, const std::string& topic) : topic_(topic) {
    g_mutex_init(&lock_);
    mosq_ = mosquitto_new(("lftag-test-sub-" + std::to_string(getpid())).c_str(), false, this);
    mosquitto_connect_callback_set(mosq_, [](mosquitto* m, void* self, int rc) {
      if (rc == 0) mosquitto_subscribe(m, nullptr, static_cast<Subscriber*>(self)->topic_.c_str(), 1);
    });
    mosquitto_subscribe_callback_set(mosq_, [](mosquitto*, void* self, int, int, const int*) {
      auto* s = static_cast<Subscriber*>(self);
      g_mutex_lock(&s->lock_);
      ++s->subscribed_;
      g_mutex_unlock(&s->lock_);
    });
    mosquitto_message_callback_set(mosq_, [](mosquitto*, void* self, const mosquitto_message* m) {
      auto* s = static_cast<Subscriber*>(self);
      g_mutex_lock(&s->lock_);
      s->messages_.emplace_back(static_cast<const char*>(m->payload), std::size_t(m->payloadlen));
      g_mutex_unlock(&s->lock_);
    });
    mosquitto_reconnect_delay_set(mosq_, 1, 1, false);
    fail_unless(mosquitto_connect(mosq_, "127.0.0.1", broker.port(), 30) == MOSQ_ERR_SUCCESS);
    fail_unless(mosquitto_loop_start(mosq_) == MOSQ_ERR_SUCCESS);
    fail_unless(wait_until([this] { return subscriptions() > 0; }), "no subscription");
  }
  ~Subscriber() {
    mosquitto_disconnect(mosq_);
    mosquitto_loop_stop(mosq_, false);
    mosquitto_destroy(mosq_);
    g_mutex_clear(&lock_);
  }
  Subscriber(const Subscriber&) = delete;
  Subscriber& operator=(const Subscriber&) = delete;
  int subscriptions() {
    g_mutex_lock(&lock_);
    const int n = subscribed_;
    g_mutex_unlock(&lock_);
    return n;
  }
  std::vector<std::string> messages() {
    g_mutex_lock(&lock_);
    std::vector<std::string> copy = messages_;
    g_mutex_unlock(&lock_);
    return copy;
  }
  // The distinct frames received.
  std::size_t frames() {
    std::set<int> seen;
    for (const std::string& m : messages()) seen.insert(nlohmann::json::parse(m).at("frame").get<int>());
    return seen.size();
  }

 private:
  std::string topic_;
  mosquitto* mosq_;
  GMutex lock_;
  int subscribed_ = 0;
  std::vector<std::string> messages_;
};

// Runs the pipeline to EOS (or an error, which fails the test), keeping its warnings.
std::vector<std::string> run_to_eos(GstElement* pipeline, std::vector<std::string> warnings = {}) {
  GstBus* bus = gst_element_get_bus(pipeline);
  while (GstMessage* m = gst_bus_timed_pop_filtered(
             bus, 300 * GST_SECOND, GstMessageType(GST_MESSAGE_EOS | GST_MESSAGE_ERROR | GST_MESSAGE_WARNING))) {
    GError* error = nullptr;
    if (GST_MESSAGE_TYPE(m) == GST_MESSAGE_ERROR) {
      gst_message_parse_error(m, &error, nullptr);
      fail("error: %s", error->message);
    }
    const bool eos = GST_MESSAGE_TYPE(m) == GST_MESSAGE_EOS;
    if (!eos) {
      gst_message_parse_warning(m, &error, nullptr);
      warnings.push_back(error->message);
      g_error_free(error);
    }
    gst_message_unref(m);
    if (eos) break;
  }
  gst_object_unref(bus);
  return warnings;
}

// The file's complete lines: polled while the publisher writes, its last line may still
// be on its way (no newline yet).
std::vector<nlohmann::json> read_lines(const std::string& path) {
  std::vector<nlohmann::json> lines;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line) && !in.eof()) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

bool any_has(const std::vector<std::string>& texts, const std::string& part) {
  for (const std::string& t : texts)
    if (t.find(part) != std::string::npos) return true;
  return false;
}

std::string scratch_file(const char* name) {
  gchar* path =
      g_build_filename(g_get_tmp_dir(), (std::string(name) + "-" + std::to_string(getpid())).c_str(), nullptr);
  std::string out = path;
  g_free(path);
  return out;
}

}  // namespace

// Every frame's message, in order, each the file target's line for the same frame.
GST_START_TEST(test_every_frame_in_order) {
  Broker broker;
  broker.start();
  Subscriber subscriber(broker, "lftag/cam1/detections");
  const std::string file = scratch_file("mqtt-every-frame.jsonl");
  GstElement* pipeline = gst_parse_launch(("lftagtestsrc num-buffers=60 ids=6789,42 ! lftagdetect deadline=0 ! "
                                           "lftagpublish name=p target=mqtt camera=cam1 broker=" +
                                           broker.address() + " ! lftagpublish location=" + file + " ! fakesink")
                                              .c_str(),
                                          nullptr);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  const std::vector<std::string> warnings = run_to_eos(pipeline);
  fail_unless(warnings.empty(), "%s", warnings.empty() ? "" : warnings[0].c_str());
  GstElement* publish = gst_bin_get_by_name(GST_BIN(pipeline), "p");
  gst_element_set_state(pipeline, GST_STATE_NULL);
  guint64 dropped = 1;
  g_object_get(publish, "dropped", &dropped, nullptr);
  fail_unless_equals_uint64(dropped, 0);
  gst_object_unref(publish);
  gst_object_unref(pipeline);

  fail_unless(wait_until([&] { return subscriber.messages().size() >= 60; }), "%zu of 60 messages came",
              subscriber.messages().size());
  const std::vector<std::string> messages = subscriber.messages();
  const std::vector<nlohmann::json> lines = read_lines(file);
  g_unlink(file.c_str());
  fail_unless_equals_int(messages.size(), 60);
  fail_unless_equals_int(lines.size(), 60);
  for (std::size_t i = 0; i < messages.size(); ++i) {
    fail_unless(messages[i].find('\n') == std::string::npos);
    const nlohmann::json message = nlohmann::json::parse(messages[i]);
    fail_unless_equals_int(message.at("frame").get<int>(), int(i));
    fail_unless(message == lines[i], "frame %zu: %s", i, messages[i].c_str());
    fail_unless_equals_int(message.at("detections").size(), 2);
  }
}
GST_END_TEST;

// The broker stops in the middle of a live stream and comes back: the messages queued
// meanwhile arrive, in order after those before; those that overflowed the queue are
// counted in "dropped", and warnings say so. Nothing else is lost.
GST_START_TEST(test_broker_restart) {
  constexpr int kFrames = 240;  // 8 s at 30 fps
  Broker broker;
  broker.start();
  Subscriber subscriber(broker, "lftag/door/detections");
  GstElement* pipeline = gst_parse_launch(
      ("lftagtestsrc is-live=true num-buffers=" + std::to_string(kFrames) +
       " ids=6789 ! lftagdetect deadline=0 ! lftagpublish name=p target=mqtt camera=door queue-size=30 "
       "flush-timeout=120000 broker=" +
       broker.address() + " ! fakesink")
          .c_str(),
      nullptr);
  GstElement* publish = gst_bin_get_by_name(GST_BIN(pipeline), "p");
  const auto dropped = [publish] {
    guint64 n = 0;
    g_object_get(publish, "dropped", &n, nullptr);
    return n;
  };
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  fail_unless(wait_until([&] { return subscriber.frames() >= 15; }), "the first messages did not come");
  broker.stop();
  // Away until the queue (30 frames, 1 s) has overflowed.
  fail_unless(wait_until([&] { return dropped() > 0; }), "nothing dropped while the broker was away");
  const std::size_t before = subscriber.frames();
  broker.start();
  std::vector<std::string> warnings = run_to_eos(pipeline);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  const guint64 lost = dropped();  // still readable once stopped
  gst_object_unref(publish);
  gst_object_unref(pipeline);

  fail_unless(lost > 0 && lost < guint64(kFrames), "%" G_GUINT64_FORMAT " dropped", lost);
  fail_unless(wait_until([&] { return subscriber.frames() >= kFrames - lost; }),
              "%zu frames came, %" G_GUINT64_FORMAT " dropped, of %d", subscriber.frames(), lost, kFrames);
  fail_unless(subscriber.frames() > before);
  fail_unless(any_has(warnings, "Lost the connection"), "no warning of the lost connection");
  fail_unless(any_has(warnings, "queue is full"), "no warning of the overflow");
  fail_unless(any_has(warnings, std::to_string(lost) + " frames' MQTT messages were dropped"), "no count at EOS");

  // In order: a frame either repeats one already received (QoS 1 resends what was not
  // acknowledged) or comes after every frame before it; exactly `lost` frames are missing.
  std::set<int> seen;
  int last = -1;
  for (const std::string& m : subscriber.messages()) {
    const int frame = nlohmann::json::parse(m).at("frame").get<int>();
    fail_unless(frame >= 0 && frame < kFrames);
    if (seen.count(frame)) continue;
    fail_unless(frame > last, "frame %d came after frame %d", frame, last);
    last = frame;
    seen.insert(frame);
  }
  fail_unless_equals_uint64(seen.size() + lost, kFrames);
  fail_unless(seen.count(0) && seen.count(kFrames - 1), "the first or last frame is missing");
}
GST_END_TEST;

// Settings that cannot work fail the start, the error saying what to fix.
GST_START_TEST(test_settings_that_cannot_work) {
  struct Case {
    const char* properties;
    const char* says;
  };
  const Case cases[] = {
      {"broker=127.0.0.1:99999", "port '99999'"},
      {"broker=http://host", "unknown scheme 'http://'"},
      {"topic=lftag/+/detections", "not a topic to publish to"},
      {"tls-ca-file=/nonexistent/ca.pem", "/nonexistent/ca.pem"},
      {"tls-cert-file=/etc/hostname", "tls-key-file"},
      {"password=secret", "needs a username"},
  };
  for (const Case& c : cases) {
    const Posted error = start_error(
        std::string("lftagtestsrc num-buffers=3 ! lftagdetect deadline=0 ! lftagpublish name=p target=mqtt ") +
        c.properties + " ! fakesink");
    fail_unless_equals_string(error.source.c_str(), "p");
    fail_unless(error.message.find(c.says) != std::string::npos, "%s: %s", c.properties, error.message.c_str());
  }
}
GST_END_TEST;

// No broker yet when the stream starts: a warning, frames flow, and the queued messages
// arrive once the broker is there.
GST_START_TEST(test_broker_not_there_yet) {
  Broker broker;
  // The subscriber's session first, kept by the broker while it is down: what the
  // element sends once the broker is back is queued for it, whenever it reconnects.
  broker.start();
  Subscriber subscriber(broker, "lftag/late/detections");
  broker.stop();
  const std::string file = scratch_file("mqtt-late.jsonl");
  GstElement* pipeline = gst_parse_launch(
      ("lftagtestsrc num-buffers=20 ids=6789 ! lftagdetect deadline=0 ! lftagpublish name=p target=mqtt "
       "camera=late flush-timeout=120000 broker=" +
       broker.address() + " ! lftagpublish location=" + file + " ! fakesink")
          .c_str(),
      nullptr);
  GstBus* bus = gst_element_get_bus(pipeline);
  fail_unless(gst_element_set_state(pipeline, GST_STATE_PLAYING) != GST_STATE_CHANGE_FAILURE);
  // Every frame went through (the second publisher wrote it) without a broker.
  fail_unless(wait_until([&] { return read_lines(file).size() == 20; }), "the frames did not flow");
  GstMessage* m = gst_bus_timed_pop_filtered(bus, 60 * GST_SECOND, GST_MESSAGE_WARNING);
  fail_unless(m != nullptr, "no warning");
  GError* error = nullptr;
  gst_message_parse_warning(m, &error, nullptr);
  fail_unless(
      std::string(error->message).find("Cannot reach the MQTT broker at " + broker.address()) != std::string::npos,
      "%s", error->message);
  g_error_free(error);
  gst_message_unref(m);
  broker.start();
  run_to_eos(pipeline);
  gst_element_set_state(pipeline, GST_STATE_NULL);
  gst_object_unref(bus);
  gst_object_unref(pipeline);
  g_unlink(file.c_str());
  fail_unless(wait_until([&] { return subscriber.frames() == 20; }), "%zu of 20 frames came", subscriber.frames());
  int last = -1;
  for (const std::string& message : subscriber.messages()) {
    const int frame = nlohmann::json::parse(message).at("frame").get<int>();
    fail_unless(frame == last + 1, "frame %d after %d", frame, last);
    last = frame;
  }
}
GST_END_TEST;

static Suite* mqtt_suite(void) {
  Suite* s = suite_create("mqtt");
  TCase* tc = tcase_create("general");
  suite_add_tcase(s, tc);
  tcase_add_test(tc, test_settings_that_cannot_work);
  tcase_add_test(tc, test_every_frame_in_order);
  tcase_add_test(tc, test_broker_not_there_yet);
  tcase_add_test(tc, test_broker_restart);
  return s;
}

int main(int argc, char** argv) {
  if (!g_file_test(LFTAG_MOSQUITTO, G_FILE_TEST_IS_EXECUTABLE)) {
    std::printf("1..0 # SKIP no mosquitto broker at %s (Debian: apt-get install mosquitto)\n", LFTAG_MOSQUITTO);
    return 77;
  }
  gst_check_init(&argc, &argv);
  mosquitto_lib_init();
  SRunner* runner = srunner_create(mqtt_suite());
  srunner_set_tap(runner, "-");
  srunner_run_all(runner, CK_SILENT);
  const int failed = srunner_ntests_failed(runner);
  srunner_free(runner);
  mosquitto_lib_cleanup();
  return failed == 0 ? 0 : 1;
}
