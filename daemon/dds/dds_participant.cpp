#include "daemon/dds/dds_participant.hpp"

#include <cstdlib>
#include <filesystem>
#include <stdexcept>

namespace pvcgel::dds {

Entity::Entity(dds_entity_t e, const char* what) : e_(e) {
  if (e < 0) {
    e_ = 0;
    throw std::runtime_error(std::string("DDS: cannot create ") + what + ": " + dds_strretcode(e));
  }
}

Entity::~Entity() {
  if (e_ > 0) dds_delete(e_);
}

Entity& Entity::operator=(Entity&& o) noexcept {
  if (this != &o) {
    if (e_ > 0) dds_delete(e_);
    e_ = o.e_;
    o.e_ = 0;
  }
  return *this;
}

Entity make_participant(const DdsSettings& s) {
  if (s.config_path.empty())
    throw std::runtime_error("DDS: no Cyclone DDS configuration given (dds.config / --dds-config); refusing to "
                             "start with the default, which discovers over every multicast interface");
  if (!std::filesystem::exists(s.config_path))
    throw std::runtime_error("DDS: configuration file '" + s.config_path + "' not found");
  const std::string uri = "file://" + std::filesystem::absolute(s.config_path).string();
  setenv("CYCLONEDDS_URI", uri.c_str(), 1);
  return Entity(dds_create_participant(static_cast<dds_domainid_t>(s.domain), nullptr, nullptr), "participant");
}

}  // namespace pvcgel::dds
