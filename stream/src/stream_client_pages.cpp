// StreamClient's page requests (RequestKind::kLoadPage, issue 28): registering page files, sending requests, and
// checking and delivering their answers. The rest of the client (and the parts pages share with mips: slot
// ownership, lost and timed-out requests, the poll loop) is in stream_client.cpp.
#include <spdlog/spdlog.h>

#include <cstring>
#include <optional>
#include <string>

#include "stream_client_internal.hpp"
#include "texstream/common/contract.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/stream/stream_client.hpp"

namespace texstream::stream {

namespace {

std::string page_name(uint32_t file, pages::PageId p) {
  return "page file " + std::to_string(file) + " level " + std::to_string(p.level) + " page " + std::to_string(p.x) +
         "," + std::to_string(p.y);
}

}  // namespace

void StreamClient::set_page_files(std::vector<std::shared_ptr<const pages::PageFile>> files, PageSink* sink) {
  TS_ASSERT(files.empty() || sink != nullptr, "set_page_files: %zu page files and no sink", files.size());
  for (size_t i = 0; i < files.size(); ++i) {
    TS_ASSERT(files[i] != nullptr, "set_page_files: page file %zu is null", i);
    // Said once here rather than by a refusal per request (the slots are sized for the scene's mips).
    if (files[i]->geometry().page_bytes() > segment_->slot_bytes()) {
      spdlog::warn(
          "stream client: the pages of page file {} ({} bytes) do not fit a staging slot ({} bytes, "
          "protocol.staging_slot_bytes): they are never requested; raise the key",
          i, files[i]->geometry().page_bytes(), segment_->slot_bytes());
    }
  }
  pages_.set_files(std::move(files), sink);
}

RequestOutcome StreamClient::try_request_page(uint32_t file, pages::PageId page, float priority) {
  IpcScope scope(*this);
  const pages::PageFile* f = pages_.file(file);
  if (f == nullptr) return RequestOutcome::kUnknownPageFile;
  const std::optional<pages::PageIndexEntry> entry = f->entry(page);
  if (!entry) return RequestOutcome::kPageNotStored;
  if (entry->bytes > segment_->slot_bytes()) return RequestOutcome::kPageTooLarge;
  if (!supervisor_->accepting_requests()) return RequestOutcome::kNoServer;
  const PageRequest r{file, page};
  if (pages_.in_flight(r)) return RequestOutcome::kAlreadyInFlight;
  if (requests_in_flight() >= static_cast<size_t>(config_.stream.max_requests_in_flight)) {
    return RequestOutcome::kInFlightLimit;
  }
  flush_releases();  // queued releases go first: the server waits for its slots
  if (endpoint_.request_free_space() <= release_reserve_) return RequestOutcome::kRingFull;
  if (!endpoint_.push_load_page(file, page, generation_, priority)) return RequestOutcome::kRingFull;
  pages_.sent(r, generation_, now());
  ++stats_.pages_requested;
  endpoint_.ring();
  return RequestOutcome::kSent;
}

void StreamClient::fail_page(PageRequest r, CompletionStatus status) {
  ++stats_.pages_failed;
  PageSink* sink = pages_.sink();
  if (sink == nullptr) return;  // the files were unregistered while it was in flight
  const auto t0 = std::chrono::steady_clock::now();
  sink->page_failed(r.file, r.page, status);
  sink_ns_ += detail::elapsed_ns(t0);  // the renderer's time, not IPC
}

void StreamClient::handle_page_record(const CheckedCompletion& c, size_t& delivered) {
  const PageRequest r{c.page_file, c.page};
  const bool ok = c.status == CompletionStatus::kOk;
  const PageRequests::InFlight* asked = pages_.find(r);  // valid until the next change of pages_
  auto refuse = [&](const std::string& what, bool release) {
    protocol_error(what + " (" + page_name(r.file, r.page) + ")");
    if (ok && release) release_slot(c.slot);
    if (asked != nullptr) {
      pages_.erase(r);
      ++stats_.completions_rejected;
      fail_page(r, CompletionStatus::kIoError);
    }
  };
  if (std::string why; ok && !take_slot(c.slot, why)) {
    refuse(why, false);
    return;
  }
  const pages::PageFile* file = pages_.file(r.file);
  if (file == nullptr) {
    refuse("a page file index the renderer did not register", true);
    return;
  }
  if (asked == nullptr) {
    refuse("an answer to a page we did not ask for (or already answered)", true);
    return;
  }
  if (c.generation != asked->generation) {
    refuse("generation " + std::to_string(c.generation.value) + " but the request had " +
               std::to_string(asked->generation.value),
           true);
    return;
  }
  if (!ok) {
    pages_.erase(r);
    fail_page(r, c.status);
    return;
  }
  // Byte size, format and side those of the file's own index entry: checked before a slot byte is read.
  if (auto st = check_against_page_file(c, *file); !st.ok()) {
    refuse(st.error().message, true);
    return;
  }
  if (deliver_page(c)) ++delivered;
}

bool StreamClient::deliver_page(const CheckedCompletion& c) {
  const PageRequest r{c.page_file, c.page};
  PageSink* sink = pages_.sink();
  if (sink == nullptr || pages_.file(r.file) == nullptr) {
    // Held for room while the renderer unregistered its page files: nobody to hand it to.
    pages_.erase(r);
    ++stats_.pages_failed;
    release_slot(c.slot);
    return true;
  }
  auto t0 = std::chrono::steady_clock::now();
  std::span<std::byte> dst = sink->reserve_page(r.file, r.page, c.byte_size);
  sink_ns_ += detail::elapsed_ns(t0);
  if (dst.empty()) {
    held_ = c;  // the slot stays ours and the request stays in flight until there is room
    return false;
  }
  TS_ASSERT(dst.size() >= c.byte_size, "PageSink::reserve_page gave %zu bytes for a %llu-byte page", dst.size(),
            static_cast<unsigned long long>(c.byte_size));
  // check_completion bounded slot < slot_count and byte_size <= slot_bytes: the read stays in the slot.
  const std::span<std::byte> src = segment_->slot(c.slot.value);
  std::memcpy(dst.data(), src.data(), c.byte_size);  // read the shared bytes once
  pages_.erase(r);
  const std::span<std::byte> payload = dst.first(c.byte_size);
  // The checksum is computed on our copy: the server may change the slot after we read it.
  if (payload_checksum(payload.data(), payload.size()) == c.checksum) {
    ++stats_.pages_ok;
    t0 = std::chrono::steady_clock::now();
    sink->commit_page(r.file, r.page, payload);
    sink_ns_ += detail::elapsed_ns(t0);
  } else {
    protocol_error("payload checksum mismatch (" + page_name(r.file, r.page) + ")");
    ++stats_.completions_rejected;
    ++stats_.payload_checksum_failures;
    fail_page(r, CompletionStatus::kIoError);
  }
  release_slot(c.slot);
  return true;
}

}  // namespace texstream::stream
