# make blender-addon: the Blender add-on (blender/heatvox_blender) as a zip for
# Preferences > Add-ons > Install, with the Python package and a stripped
# libheatvox inside it. make check-blender: its tests, inside Debian's Blender
# (installed when missing), headless; they also render the add-on's volume
# and Blender's own Mesh to Volume of one broken mesh into $(BUILD)/blender/.
BLENDER_ZIP := $(BUILD)/heatvox_blender.zip
BLENDER_SRC := $(sort $(wildcard blender/heatvox_blender/*.py))

.PHONY: blender-addon check-blender
blender-addon: $(BLENDER_ZIP) ## the Blender add-on, $(BUILD)/heatvox_blender.zip
$(BLENDER_ZIP): $(BLENDER_SRC) $(PY_SRC) $(LIB_SO) tools/blender_zip.py
	@python3 tools/blender_zip.py $@ blender/heatvox_blender python/heatvox $(LIB_SO)

# The add-on is installed into a scripts directory of the run's own
# (BLENDER_USER_SCRIPTS), never the user's; the scenes are generated for it.
check-blender: $(BLENDER_ZIP) $(BIN) $(STAGE)/.installed | $(BLENDER_STAMP) ## the add-on's tests inside Blender
	@rm -rf $(BUILD)/blender && mkdir -p $(BUILD)/blender
	@$(BIN) make-scenes $(BUILD)/blender/scenes > /dev/null
	@s0=$$(date +%s); \
	BLENDER_USER_SCRIPTS=$(CURDIR)/$(BUILD)/blender/scripts BLENDER_USER_CONFIG=$(CURDIR)/$(BUILD)/blender/config \
	  timeout 600 blender -b --factory-startup --python-exit-code 1 -P tests/blender/check_addon.py -- \
	  $(BLENDER_ZIP) $(BUILD)/blender > $(BUILD)/blender/check.log 2>&1; rc=$$?; \
	grep -vE '^(Read prefs|Blender quit|Fra:|$$)' $(BUILD)/blender/check.log; \
	echo "check-blender: exit $$rc in $$(( $$(date +%s) - s0 )) s"; exit $$rc
