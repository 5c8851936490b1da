/* SPDX-License-Identifier: LGPL-2.1-or-later */
#include "mqttsender.h"

#include <mosquitto.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

GST_DEBUG_CATEGORY_STATIC(lftag_mqtt_debug);
#define GST_CAT_DEFAULT lftag_mqtt_debug

namespace lftag::gst {
namespace {

/* Messages handed to libmosquitto and not yet acknowledged, at most: enough to keep a
 * link of 100 ms round trip busy at 30 frames a second, few enough that what is not yet
 * acknowledged when the broker goes away stays small beside the queue. */
constexpr std::size_t kWindow = 64;
/* Reconnection delays: 1 s, doubled after each failure, at most 30 s. */
constexpr unsigned kFirstDelay = 1, kMaxDelay = 30;
constexpr int kKeepAlive = 30;

bool readable(const std::string& path) { return access(path.c_str(), R_OK) == 0; }

}  // namespace

bool parse_broker(const std::string& address, MqttSettings& out, std::string& why) {
  std::string rest = address;
  bool tls = false;
  const std::size_t scheme = rest.find("://");
  if (scheme != std::string::npos) {
    const std::string name = rest.substr(0, scheme);
    if (name == "mqtts" || name == "ssl" || name == "tls") {
      tls = true;
    } else if (name != "mqtt" && name != "tcp") {
      why = "unknown scheme '" + name + "://' (use mqtt:// or mqtts://)";
      return false;
    }
    rest = rest.substr(scheme + 3);
  }
  if (!rest.empty() && rest.back() == '/') rest.pop_back();
  std::string host = rest, port;
  if (!rest.empty() && rest[0] == '[') {  // [v6 address]:port
    const std::size_t close = rest.find(']');
    if (close == std::string::npos) {
      why = "no ']' after the IPv6 address";
      return false;
    }
    host = rest.substr(1, close - 1);
    if (close + 1 < rest.size()) {
      if (rest[close + 1] != ':') {
        why = "expected ':PORT' after ']'";
        return false;
      }
      port = rest.substr(close + 2);
    }
  } else if (rest.find(':') != std::string::npos) {
    host = rest.substr(0, rest.rfind(':'));
    port = rest.substr(rest.rfind(':') + 1);
  }
  if (host.empty() || host.find_first_of("/ ") != std::string::npos) {
    why = "no host name (use HOST, HOST:PORT or mqtt://HOST:PORT)";
    return false;
  }
  int number = tls ? 8883 : 1883;
  if (!port.empty() || rest.back() == ':') {
    char* end = nullptr;
    errno = 0;
    const long value = std::strtol(port.c_str(), &end, 10);
    if (port.empty() || *end != '\0' || errno != 0 || value < 1 || value > 65535) {
      why = "port '" + port + "' is not a number from 1 to 65535";
      return false;
    }
    number = int(value);
  }
  out.host = host;
  out.port = number;
  out.tls = out.tls || tls;
  return true;
}

bool MqttSender::start(const MqttSettings& settings, std::string& why) {
  static std::once_flag once;
  std::call_once(once, [] {
    GST_DEBUG_CATEGORY_INIT(lftag_mqtt_debug, "lftagmqtt", 0, "lftagpublish's MQTT target");
    mosquitto_lib_init();
  });
  settings_ = settings;
  stopping_ = false;  // before any thread that reads it starts
  if (mosquitto_pub_topic_check(settings_.topic.c_str()) != MOSQ_ERR_SUCCESS) {
    why = "'" + settings_.topic + "' is not a topic to publish to (not empty, no '+' or '#')";
    return false;
  }
  for (const std::string* file : {&settings_.ca_file, &settings_.cert_file, &settings_.key_file}) {
    if (!file->empty() && !readable(*file)) {
      why = "cannot read the TLS file '" + *file + "': " + g_strerror(errno);
      return false;
    }
  }
  if (settings_.cert_file.empty() != settings_.key_file.empty()) {
    why = "a TLS client certificate needs both tls-cert-file and tls-key-file";
    return false;
  }
  if (!settings_.password.empty() && settings_.username.empty()) {
    why = "a password needs a username";
    return false;
  }

  mosq_ = mosquitto_new(settings_.client_id.c_str(), true, this);
  if (!mosq_) {
    why = std::string("cannot make an MQTT client: ") + g_strerror(errno);
    return false;
  }
  mosquitto_int_option(mosq_, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
  mosquitto_connect_callback_set(
      mosq_, [](struct mosquitto*, void* self, int rc) { static_cast<MqttSender*>(self)->on_connect(rc); });
  mosquitto_disconnect_callback_set(
      mosq_, [](struct mosquitto*, void* self, int rc) { static_cast<MqttSender*>(self)->on_disconnect(rc); });
  mosquitto_publish_callback_set(
      mosq_, [](struct mosquitto*, void* self, int) { static_cast<MqttSender*>(self)->on_publish(); });
  mosquitto_reconnect_delay_set(mosq_, kFirstDelay, kMaxDelay, true);
  mosquitto_max_inflight_messages_set(mosq_, unsigned(kWindow));
  int rc = MOSQ_ERR_SUCCESS;
  if (!settings_.username.empty())
    rc = mosquitto_username_pw_set(mosq_, settings_.username.c_str(),
                                   settings_.password.empty() ? nullptr : settings_.password.c_str());
  if (rc == MOSQ_ERR_SUCCESS && (settings_.tls || !settings_.ca_file.empty() || !settings_.cert_file.empty())) {
    // Without a CA file the system's certificates decide.
    if (settings_.ca_file.empty()) mosquitto_int_option(mosq_, MOSQ_OPT_TLS_USE_OS_CERTS, 1);
    rc = mosquitto_tls_set(mosq_, settings_.ca_file.empty() ? nullptr : settings_.ca_file.c_str(), nullptr,
                           settings_.cert_file.empty() ? nullptr : settings_.cert_file.c_str(),
                           settings_.key_file.empty() ? nullptr : settings_.key_file.c_str(), nullptr);
    if (rc != MOSQ_ERR_SUCCESS) {
      why = std::string("cannot set up TLS: ") + mosquitto_strerror(rc) +
            " (check tls-ca-file, tls-cert-file and tls-key-file)";
      stop();
      return false;
    }
  }
  if (rc != MOSQ_ERR_SUCCESS) {
    why = std::string("cannot set the username: ") + mosquitto_strerror(rc);
    stop();
    return false;
  }

  rc = mosquitto_connect_async(mosq_, settings_.host.c_str(), settings_.port, kKeepAlive);
  if (rc == MOSQ_ERR_INVAL) {
    why = "cannot connect to " + settings_.host + ":" + std::to_string(settings_.port) + ": invalid address";
    stop();
    return false;
  }
  const bool connecting = rc == MOSQ_ERR_SUCCESS;
  if (!connecting) {
    // Not there yet (a broker that starts after the camera): the sender thread retries
    // (libmosquitto's network thread only reconnects after a first connection).
    const char* reason = rc == MOSQ_ERR_ERRNO ? g_strerror(errno) : mosquitto_strerror(rc);
    GST_ELEMENT_WARNING(element_, RESOURCE, OPEN_WRITE,
                        ("Cannot reach the MQTT broker at %s:%d yet (%s): retrying every %u s to %u s; up to %zu "
                         "frames' detections are kept meanwhile.",
                         settings_.host.c_str(), settings_.port, reason, kFirstDelay, kMaxDelay, settings_.queue_size),
                        (nullptr));
    warned_unreachable_ = true;
  } else {
    rc = mosquitto_loop_start(mosq_);
    if (rc != MOSQ_ERR_SUCCESS) {
      why = std::string("cannot start the MQTT network thread: ") + mosquitto_strerror(rc);
      stop();
      return false;
    }
  }
  sender_ = std::thread([this, connecting] {
    if (connecting || connect_first()) send_loop();
  });
  GST_INFO_OBJECT(element_, "publishing to %s:%d, topic %s, QoS %d, client id %s", settings_.host.c_str(),
                  settings_.port, settings_.topic.c_str(), settings_.qos, settings_.client_id.c_str());
  return true;
}

bool MqttSender::push(std::string payload) {
  bool first_drop = false;
  std::uint64_t dropped = 0;
  {
    std::lock_guard<std::mutex> lock(lock_);
    if (queue_.size() < settings_.queue_size) {
      queue_.push_back(std::move(payload));
      changed_.notify_all();
      return true;
    }
    dropped = ++dropped_;
    first_drop = !overflowing_;
    overflowing_ = true;
  }
  // Once per outage; posted outside the lock, which a bus handler reading the "dropped"
  // property would take.
  if (first_drop)
    GST_ELEMENT_WARNING(element_, RESOURCE, WRITE,
                        ("The MQTT queue is full (%zu messages) while the broker at %s:%d is away: the detections of "
                         "new frames are dropped until it is back (%" G_GUINT64_FORMAT
                         " so far; the \"dropped\" property counts them).",
                         settings_.queue_size, settings_.host.c_str(), settings_.port, dropped),
                        (nullptr));
  return false;
}

/* In the sender thread, when the first attempt failed: tries again after 1 s, then twice
 * as long each time up to 30 s, until connected (then libmosquitto's network thread takes
 * over, reconnections included) or stopped. */
bool MqttSender::connect_first() {
  for (unsigned delay = kFirstDelay;; delay = std::min(2 * delay, kMaxDelay)) {
    {
      std::unique_lock<std::mutex> lock(lock_);
      if (changed_.wait_for(lock, std::chrono::seconds(delay), [this] { return stopping_; })) return false;
    }
    if (mosquitto_reconnect_async(mosq_) == MOSQ_ERR_SUCCESS && mosquitto_loop_start(mosq_) == MOSQ_ERR_SUCCESS)
      return true;
    GST_DEBUG_OBJECT(element_, "no broker at %s:%d yet", settings_.host.c_str(), settings_.port);
  }
}

/* The sender thread: the queue's head to libmosquitto, in order, while connected and
 * fewer than kWindow messages wait for their acknowledgement. Never calls libmosquitto
 * with the lock held, so its callbacks (which take the lock) cannot deadlock with it. */
void MqttSender::send_loop() {
  std::unique_lock<std::mutex> lock(lock_);
  while (true) {
    changed_.wait(lock, [this] { return stopping_ || (connected_ && in_flight_ < kWindow && !queue_.empty()); });
    if (stopping_) return;
    std::string payload = std::move(queue_.front());
    queue_.pop_front();
    ++in_flight_;
    lock.unlock();
    const int rc = mosquitto_publish(mosq_, nullptr, settings_.topic.c_str(), int(payload.size()), payload.data(),
                                     settings_.qos, false);
    lock.lock();
    // At QoS 1 and 2 libmosquitto keeps the message even when the connection has just
    // gone (MOSQ_ERR_NO_CONN), and resends it once connected again.
    if (rc == MOSQ_ERR_SUCCESS || (rc == MOSQ_ERR_NO_CONN && settings_.qos > 0)) continue;
    --in_flight_;
    if (rc == MOSQ_ERR_NO_CONN) {
      queue_.push_front(std::move(payload));  // QoS 0: sent again once connected
      connected_ = false;
      continue;
    }
    // A message the broker can never take (say, over its size limit): this frame's only.
    ++dropped_;
    lock.unlock();  // logging may take the element's lock, under which "dropped" is read
    GST_WARNING_OBJECT(element_, "a message of %zu bytes was not published: %s", payload.size(),
                       mosquitto_strerror(rc));
    lock.lock();
  }
}

void MqttSender::on_connect(int rc) {
  if (rc != 0) {
    // Refused (bad credentials, client id rejected...): a configuration to fix.
    GST_ELEMENT_ERROR(element_, RESOURCE, OPEN_WRITE,
                      ("The MQTT broker at %s:%d refused the connection: %s (check username, password and "
                       "client-id).",
                       settings_.host.c_str(), settings_.port, mosquitto_connack_string(rc)),
                      (nullptr));
    return;
  }
  bool again;
  {
    std::lock_guard<std::mutex> lock(lock_);
    again = ever_connected_;
    ever_connected_ = connected_ = true;
    overflowing_ = warned_unreachable_ = false;
    changed_.notify_all();
  }
  if (again)
    GST_ELEMENT_INFO(element_, RESOURCE, OPEN_WRITE,
                     ("Connected to the MQTT broker at %s:%d again.", settings_.host.c_str(), settings_.port),
                     (nullptr));
  else
    GST_INFO_OBJECT(element_, "connected to %s:%d", settings_.host.c_str(), settings_.port);
}

void MqttSender::on_disconnect(int rc) {
  bool expected, was_connected, first;
  {
    std::lock_guard<std::mutex> lock(lock_);
    was_connected = connected_;
    connected_ = false;
    // QoS 0 messages are not acknowledged: written or lost, they wait no more.
    if (settings_.qos == 0) in_flight_ = 0;
    expected = stopping_ || rc == 0;
    // Said once per outage, not at every failed attempt.
    first = was_connected || !warned_unreachable_;
    if (!was_connected) warned_unreachable_ = true;
    changed_.notify_all();
  }
  if (expected || !first) return;
  if (was_connected)
    GST_ELEMENT_WARNING(element_, RESOURCE, WRITE,
                        ("Lost the connection to the MQTT broker at %s:%d: reconnecting (every %u s to %u s); up to "
                         "%zu frames' detections are kept meanwhile.",
                         settings_.host.c_str(), settings_.port, kFirstDelay, kMaxDelay, settings_.queue_size),
                        ("%s", mosquitto_strerror(rc)));
  else
    GST_ELEMENT_WARNING(element_, RESOURCE, OPEN_WRITE,
                        ("Cannot reach the MQTT broker at %s:%d: retrying (every %u s to %u s); up to %zu frames' "
                         "detections are kept meanwhile.",
                         settings_.host.c_str(), settings_.port, kFirstDelay, kMaxDelay, settings_.queue_size),
                        ("%s", mosquitto_strerror(rc)));
}

void MqttSender::on_publish() {
  std::lock_guard<std::mutex> lock(lock_);
  if (in_flight_ > 0) --in_flight_;
  ++sent_;
  changed_.notify_all();
}

std::size_t MqttSender::flush(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(lock_);
  changed_.wait_for(lock, timeout, [this] { return queue_.empty() && in_flight_ == 0; });
  return queue_.size() + in_flight_;
}

void MqttSender::stop() {
  if (!mosq_) return;
  {
    std::lock_guard<std::mutex> lock(lock_);
    stopping_ = true;
    changed_.notify_all();
  }
  if (sender_.joinable()) sender_.join();
  mosquitto_disconnect(mosq_);
  // Not forced: libmosquitto wakes its thread from a back-off wait itself.
  mosquitto_loop_stop(mosq_, false);
  mosquitto_destroy(mosq_);
  mosq_ = nullptr;
  GST_INFO_OBJECT(element_, "MQTT: %" G_GUINT64_FORMAT " messages acknowledged, %" G_GUINT64_FORMAT " dropped", sent_,
                  dropped_);
}

std::uint64_t MqttSender::dropped() const {
  std::lock_guard<std::mutex> lock(lock_);
  return dropped_;
}

std::uint64_t MqttSender::sent() const {
  std::lock_guard<std::mutex> lock(lock_);
  return sent_;
}

}  // namespace lftag::gst
